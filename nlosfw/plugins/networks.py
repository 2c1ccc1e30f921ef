"""Networks registered for the shared neural trainer, and the field models made from them.

A plugin module registers a network in its ``register_networks(register)`` hook::

    register("example_fourier", backend="torch",
             factory="my_package.network:build",      # factory(config, shape) -> nn.Module
             config="my_package.hooks:FourierConfig",  # derives from NeuralFieldConfig
             description="Fourier-feature MLP")

and the registry then holds the field-model plugin ``example_fourier_torch``: a
:class:`~nlosfw.model.neural.NeuralFieldModel` bound to that network and to the backend,
selectable as ``model=example_fourier_torch`` and checked by the conformance kit.
Nothing is imported at registration: the factory, and with it torch or JAX, is
imported when the model is first used. (``engine=``, the keyword's old name, still works,
with a DeprecationWarning.)
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any, TypedDict

from nlosfw.common.deprecation import REMOVED_IN, moved_names
from nlosfw.common.errors import PluginError
from nlosfw.model.neural.catalogue import (
    FIELD_NETWORKS,
    THESIS_NETWORKS,
    THESIS_TEST_CONFIG,
    presets_of,
)
from nlosfw.model.neural.config import NeuralFieldConfig, Preset
from nlosfw.model.neural.trainer import NeuralFieldModel
from nlosfw.plugins.capabilities import Capability
from nlosfw.plugins.registry import (
    LazyFactory,
    Registrar,
    import_object,
    registration_options,
)

if TYPE_CHECKING:
    from typing_extensions import Unpack


class NetworkBackend(str, Enum):
    """The backends a network can run on (the plugin that provides each)."""

    torch = "torch"
    """A ``torch.nn.Module`` (any); ``factory(config, shape)``; plugin ``nlosfw-torch``."""
    jax = "jax"
    """An equinox module trained with optax; ``factory(config, shape, key)``; ``nlosfw-jax``."""


#: Backend class and the (module, pip requirement) pairs it needs, per backend.
BACKENDS: dict[NetworkBackend, tuple[str, Mapping[str, str]]] = {
    NetworkBackend.torch: ("nlosfw_torch.backend:TorchBackend",
                           {"nlosfw_torch": "nlosfw-torch", "torch": "torch==2.13.0"}),
    NetworkBackend.jax: ("nlosfw_jax.backend:JaxBackend",
                         {"nlosfw_jax": "nlosfw-jax", "jax": "jax", "optax": "optax",
                          "equinox": "equinox"}),
}

#: This module's names before "engine" came to mean the run engine only (deprecated).
__getattr__ = moved_names(__name__, {"NetworkEngine": f"{__name__}:NetworkBackend",
                                     "ENGINES": f"{__name__}:BACKENDS"})

_TITLES = {"torch": "PyTorch", "jax": "JAX"}

#: What every network trained by the shared trainer can do, unless it declares otherwise.
NETWORK_CAPABILITIES = (Capability.MULTI_FREQUENCY, Capability.SAVE_LOAD, Capability.NEURAL,
                        Capability.GPU)


@dataclass(frozen=True)
class NetworkSpec(LazyFactory):
    """One registered network: builds its field-model class on first use."""

    name: str
    backend: NetworkBackend
    factory: str | Callable[..., Any]
    """``factory(config, shape)`` (JAX: ``(config, shape, key)``), or ``"module:function"``."""
    config: str | type
    """Its config dataclass (deriving from NeuralFieldConfig), or ``"module:Class"``."""
    description: str = ""
    presets: Mapping[str, Preset] = field(default_factory=dict)
    _bound: dict[str, type[NeuralFieldModel]] = field(default_factory=dict, compare=False,
                                                      repr=False)

    @property
    def model_name(self) -> str:
        """The field model's name: ``<name>_<backend>``."""
        return f"{self.name}_{self.backend.value}"

    @property
    def engine(self) -> NetworkBackend:
        """Deprecated: :attr:`backend`."""
        warnings.warn(f"NetworkSpec.engine is deprecated and will be removed in nlosfw "
                      f"{REMOVED_IN}: use NetworkSpec.backend", DeprecationWarning, stacklevel=2)
        return self.backend

    def load(self) -> type[NeuralFieldModel]:
        """The :class:`NeuralFieldModel` subclass running this network (imported once)."""
        if "model" not in self._bound:
            self._bound["model"] = network_model(self)
        return self._bound["model"]

    def import_paths(self) -> tuple[str, ...]:
        """The backend's, the factory's and the config's import paths."""
        return tuple(p for p in (BACKENDS[self.backend][0], self.factory, self.config)
                     if isinstance(p, str))


def network_model(spec: NetworkSpec) -> type[NeuralFieldModel]:
    """A :class:`NeuralFieldModel` subclass for ``spec`` (imports the factory and backend)."""
    what = f"model plugin '{spec.model_name}'"
    try:
        backend = import_object(BACKENDS[spec.backend][0])
        factory = import_object(spec.factory) if isinstance(spec.factory, str) else spec.factory
        config = import_object(spec.config) if isinstance(spec.config, str) else spec.config
    except (ImportError, AttributeError) as err:
        raise PluginError(f"{what} cannot be imported: {err}") from None
    if not (isinstance(config, type) and issubclass(config, NeuralFieldConfig)):
        raise PluginError(f"{what}: its config {config!r} must be a dataclass deriving from "
                          "nlosfw.model.NeuralFieldConfig")
    title = "".join(part.capitalize() for part in spec.model_name.split("_"))
    return type(title, (NeuralFieldModel,), {
        "__doc__": spec.description or f"The network {spec.name} on the "
                                       f"{spec.backend.value} backend.",
        "__module__": __name__,
        "config_class": config, "family": spec.name, "backend": spec.backend.value,
        "backend_class": backend, "network_factory": staticmethod(factory),
        "network_presets": dict(spec.presets),
    })


@dataclass(frozen=True)
class NetworkOptions:
    """The keyword options of ``register(name, **options)`` in a ``register_networks`` hook."""

    factory: str | Callable[..., Any]
    """Builds the network: ``"module:function"`` (imported on first use) or a callable."""
    config: str | type
    """Its options, a dataclass deriving from NeuralFieldConfig (or ``"module:Class"`` in a
    module that imports neither torch nor JAX: the CLI reads it to list the options)."""
    backend: str = ""
    """``torch`` or ``jax`` (required): the field model is named ``<name>_<backend>``."""
    engine: str = ""
    """Deprecated: ``backend``'s old name (a DeprecationWarning; give one of the two)."""
    description: str = ""
    requires: Mapping[str, str] | None = None
    """Further importable modules the network needs -> their pip requirements."""
    test_config: Mapping[str, object] | None = None
    """Small, fast options for the conformance kit."""
    expected_failures: Mapping[str, str] | None = None
    """Conformance check name -> why it is expected to fail."""
    presets: Mapping[str, Preset] | None = None
    """Published configurations, whose parameter counts the kit checks."""
    capabilities: Iterable[str | Capability] | None = None
    """What the field model can do (field-model vocabulary of
    :data:`nlosfw.plugins.capabilities.VOCABULARY`); default :data:`NETWORK_CAPABILITIES`."""


class NetworkKwargs(TypedDict, total=False):
    """The keyword options of a ``register(name, ...)`` call in a ``register_networks`` hook,
    typed (what they mean: :class:`NetworkOptions`; ``backend``, ``factory`` and ``config``
    are required)."""

    backend: str
    engine: str
    factory: str | Callable[..., Any]
    config: str | type
    description: str
    requires: Mapping[str, str] | None
    test_config: Mapping[str, object] | None
    expected_failures: Mapping[str, str] | None
    presets: Mapping[str, Preset] | None
    capabilities: Iterable[str | Capability] | None


@dataclass
class NetworkRegistrar:
    """The ``register`` callable handed to ``register_networks`` hooks of one plugin module;
    it registers field models through ``models`` (the module's field-model registrar)."""

    models: Registrar

    def __call__(self, name: str, **options: Unpack[NetworkKwargs]) -> None:
        """Register network ``name`` as the field model ``<name>_<backend>`` (see
        :class:`NetworkOptions`)."""
        who = f"{self.models.distribution}: network {name!r}"
        opts = registration_options(NetworkOptions, options, who)
        if opts.engine:
            if opts.backend:
                raise PluginError(f"{who} is registered with both backend and engine (its "
                                  "old name); give backend only")
            warnings.warn(f"{who}: register(..., engine=...) is deprecated and will be "
                          f"removed in nlosfw {REMOVED_IN}: write backend=...",
                          DeprecationWarning, stacklevel=2)
        chosen = opts.backend or opts.engine
        valid = ", ".join(b.value for b in NetworkBackend)
        if not chosen:
            raise PluginError(f"{who} is registered with no 'backend'; valid: {valid}")
        try:
            backend = NetworkBackend(chosen)
        except ValueError:
            raise PluginError(f"{who} names backend {chosen!r}; valid: {valid}") from None
        network = NetworkSpec(name, backend, opts.factory, opts.config, opts.description,
                              dict(opts.presets or {}))
        self.models(network.model_name, network, config=opts.config,
                    requires={**BACKENDS[backend][1], **dict(opts.requires or {})},
                    description=opts.description, test_config=opts.test_config,
                    expected_failures=opts.expected_failures,
                    capabilities=(NETWORK_CAPABILITIES if opts.capabilities is None
                                  else opts.capabilities))


#: Checks a thesis network is known to fail with the kit's short test fits.
_THESIS_KNOWN_FAILURES = {
    "tanh": {"check_fits_smooth_field[single_frequency]":
             "one small tanh MLP per frequency reaches a relative L2 error of about 0.155 on "
             "the kit's smooth field in 300 steps, above its 0.15 tolerance (thesis fig. 4.2: "
             "tanh networks fit phasor fields poorly)"},
}


def register_thesis_networks(register: Callable[..., None], backend: str, factory: str
                             ) -> None:
    """Register tanh, pe and siren for ``backend``, all built by ``factory`` (which reads the
    network from its config's class, see :func:`nlosfw.model.neural.thesis_architecture`)."""
    for name, network in THESIS_NETWORKS.items():
        register(name, backend=backend, factory=factory, config=network.config,
                 description=f"{network.description}, {_TITLES[backend]}",
                 test_config={**THESIS_TEST_CONFIG, "lr": network.test_lr},
                 presets=presets_of(name),
                 capabilities=(*NETWORK_CAPABILITIES, Capability.SINGLE_FREQUENCY),
                 expected_failures=_THESIS_KNOWN_FAILURES.get(name))


def register_field_networks(register: Callable[..., None], backend: str, factory: str) -> None:
    """Register fourier, wire, finer and hashgrid for ``backend``, all built by
    ``factory`` (which reads the network from its config's class)."""
    for name, network in FIELD_NETWORKS.items():
        register(name, backend=backend, factory=factory, config=network.config,
                 description=f"{network.description}, {_TITLES[backend]}",
                 test_config=dict(network.test_config),
                 capabilities=(*NETWORK_CAPABILITIES, Capability.SINGLE_FREQUENCY))


def thesis_network_model(name: str, backend: str, factory: str) -> type[NeuralFieldModel]:
    """The field-model class of thesis network ``name`` on ``backend`` (as registered)."""
    network = THESIS_NETWORKS[name]
    return NetworkSpec(name, NetworkBackend(backend), factory, network.config,
                       f"{network.description}, {_TITLES[backend]}",
                       presets_of(name)).load()


#: Small, fast options of ``rsd_residual_<backend>`` for the conformance kit: a short physics
#: fit (the kit's plane-wave field is no hidden scene's) and a small network for the rest.
RSD_RESIDUAL_TEST_CONFIG: Mapping[str, object] = {
    "prior": {"iterations": 10, "amplitude": "point", "l1_weight": 0.2, "workers": 1,
              "depth": {"range": [0.3, 0.7], "step": 0.1}, "fit_frequencies": 0,
              "power_iterations": 5},
    "residual_weight": 0.0, "network_steps": 150, "network_lr": 2e-3, "network_batch_size": 0,
    "network_validation_fraction": 0.0}


def register_rsd_residual(register: Callable[..., None], backend: str, factory: str) -> None:
    """Register ``rsd_residual_<backend>`` (``register`` is a ``register_field_models``
    hook's): rsd_prior's field plus a penalised residual network, the class ``factory``
    (a subclass of :class:`nlosfw.model.hybrid.RSDResidualFieldModel` for ``backend``)."""
    register(
        f"rsd_residual_{backend}", factory,
        config="nlosfw.model.hybrid.residual:RSDResidualConfig",
        requires=dict(BACKENDS[NetworkBackend(backend)][1]),
        description=f"rsd_prior's field plus a small penalised residual network, "
                    f"{_TITLES[backend]}",
        test_config=dict(RSD_RESIDUAL_TEST_CONFIG),
        # not physical_prior: the residual network represents fields no hidden scene makes
        capabilities=NETWORK_CAPABILITIES)


#: Small, fast options of ``neural_volume_<backend>`` for the conformance kit (the kit's
#: point scatterer at 0.5 m, amplitude "point"): a few planes, a small network.
NEURAL_VOLUME_TEST_CONFIG: Mapping[str, object] = {
    "prior": {"amplitude": "point", "depth": {"range": [0.4, 0.6], "step": 0.05}, "workers": 1},
    "network_hidden": [32, 32], "steps": 200, "device": "cpu"}


def register_neural_volume(register: Callable[..., None], backend: str, factory: str) -> None:
    """Register ``neural_volume_<backend>`` (``register`` is a ``register_field_models``
    hook's): a registered network's non-negative albedo on rsd_prior's lattice, propagated
    by RSD, the class ``factory`` (a subclass of
    :class:`nlosfw.model.hybrid.NeuralVolumeFieldModel` for ``backend``)."""
    register(
        f"neural_volume_{backend}", factory,
        config="nlosfw.model.hybrid.volume_config:NeuralVolumeConfig",
        requires=dict(BACKENDS[NetworkBackend(backend)][1]),
        description=f"a network's non-negative hidden albedo propagated to the wall by RSD, "
                    f"{_TITLES[backend]}",
        test_config=dict(NEURAL_VOLUME_TEST_CONFIG),
        # physical_prior: like rsd_prior it makes only fields a hidden scene can produce
        capabilities=(*NETWORK_CAPABILITIES, Capability.PHYSICAL_PRIOR))


#: Small, fast options of ``ensemble_<backend>`` for the conformance kit: its members' own
#: (the kit's plane-wave field is no hidden scene's: the volume may find nothing to fit, and
#: is then left out).
ENSEMBLE_TEST_CONFIG: Mapping[str, object] = {
    "prior": RSD_RESIDUAL_TEST_CONFIG["prior"], "tv_weights": [0.0, 0.1],
    "residual": {k: v for k, v in RSD_RESIDUAL_TEST_CONFIG.items() if k != "prior"},
    "volume": {k: v for k, v in NEURAL_VOLUME_TEST_CONFIG.items() if k != "device"},
    "device": "cpu"}


def register_ensemble(register: Callable[..., None], backend: str, factory: str) -> None:
    """Register ``ensemble_<backend>`` (``register`` is a ``register_field_models`` hook's):
    ``rsd_prior``, the neural residual and the neural volume weighed by their error at
    held-out kept wall points, the class ``factory`` (a subclass of
    :class:`nlosfw.model.hybrid.EnsembleFieldModel` for ``backend``)."""
    register(
        f"ensemble_{backend}", factory,
        config="nlosfw.model.hybrid.ensemble_config:EnsembleConfig",
        requires=dict(BACKENDS[NetworkBackend(backend)][1]),
        description=f"use it on a measured capture when unsure which field model fits it "
                    f"(the real-data study's default): rsd_prior at three TV weights and the "
                    f"neural volume weighed on held-out kept points, plus a residual network, "
                    f"{_TITLES[backend]}",
        test_config=dict(ENSEMBLE_TEST_CONFIG),
        # not physical_prior: its residual members represent fields no hidden scene makes
        capabilities=NETWORK_CAPABILITIES)
