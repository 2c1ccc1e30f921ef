"""The memory a neural field model holds while it trains, estimated without importing it.

A neural model brings a runtime (PyTorch, JAX) whose import alone takes about 150-200 MB,
whose first training adds its own working memory (thread pools, allocator caches, JAX's
compiled programs), and which then holds, per run, the training samples in its own formats
and a batch's activations, gradients and Adam state. The backend of a model is read from
what its plugin declares it needs (``requires``: ``torch``, ``jax``), so nothing is imported
to estimate it. For a model whose backend is B, with N = F·S·L training samples (F
frequencies, S sensor points, L laser points), a batch of b samples and hidden layers of
widths w₁ … wₖ (``hidden``, or ``network_hidden`` for a residual network; a Fourier-feature
encoding's 2·``features`` outputs count as one more):

===================  =======================================================================
the runtime          IMPORT[B] when B is not imported yet (once it is, the program's
                     resident memory counts it) + WORKING[B] (its first training)
training data        PER_SAMPLE[B]·N (inputs, targets, the validation split, predictions)
training activations PER_ACTIVATION[B]·b·(w₁ + … + wₖ)
network parameters   PER_PARAMETER[B]·P, P the networks' parameters (one network in ``multi``
                     mode, one per frequency in ``single`` mode)
===================  =======================================================================

P is counted from the network's own description: the arrays its config's
:meth:`~nlosfw.model.NeuralFieldConfig.network_shapes` lists for the field's shape (layer
widths, a hash grid's tables, ...), the config built from the run's options over its
class's defaults by the plugin's declared config class (:class:`ModelCatalogue`; nothing is
allocated and no backend imported). A model that trains a registered network of its own
(``rsd_residual_*``, ``neural_volume_*``) names it ``network``, its widths
``network_hidden`` and any other option of it in ``network_options``. Training holds
four float32 copies of every parameter (the weights, their gradients and Adam's two
moments: 16 bytes); the engines' initial weights (drawn in float64 by numpy, then
converted) and the best step's copy bring the peak to PER_PARAMETER, fitted to the peak
added by a fit of ``siren_<B>`` with hidden layers [3000, 3000] and [6000, 6000]
(9.0 and 36.0 million parameters: 390 and 1270 MB with torch, 388 and 1103 MB with jax,
slopes of 33 and 27 bytes per parameter).

The figures (:data:`BACKENDS`) were measured on the project's CPU machine (x86_64, torch
2.13.0 CPU, jax 0.10.2 CPU, float32) with ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` and
``/proc/self/statm`` around ``nlosfw.api.fit_model(smooth_field(n, F), "siren_<B>",
steps=100, ...)`` in a fresh process: IMPORT is the resident memory added by loading the
model's plugin (``spec.load()``: the engine and the backend); the rest was fitted to the peak
added by the fit over 32 × 32 and 64 × 64 fields of 16 and 151 frequencies, batches of 2048
and 8192 samples and hidden layers [64, 64, 64] and [256, 256, 256] (each figure within
0.8-1.2 of the measured peak). Peaks measured, MB above the imported backend:

========================================  ========  =======
field, batch, hidden                      torch     jax
========================================  ========  =======
32 × 32 × 16, 8192, [64, 64, 64]          173       242
32 × 32 × 151, 8192, [64, 64, 64]         160       263
64 × 64 × 151, 8192, [64, 64, 64]         228       394
64 × 64 × 151, 2048, [64, 64, 64]         192       344
64 × 64 × 151, 8192, [256, 256, 256]      502       644
========================================  ========  =======
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from nlosfw.common.errors import NlosfwError
from nlosfw.plugins.kinds import PluginKind

if TYPE_CHECKING:
    from nlosfw.model.neural import FieldShape
    from nlosfw.plugins import PluginHost
    from nlosfw.plugins.registry import PluginSpec, Registry

#: The modules a field model named so needs (as its plugin declares them), or () when unknown.
ModelRequires = Callable[[str], Iterable[str]]

_MB = 1e6


@dataclass(frozen=True)
class BackendMemory:
    """What a neural-network backend holds while a model trains on it (bytes)."""

    imported: float
    """Resident memory added by importing it (and the model's engine)."""
    working: float
    """Added by its first training, whatever its size (threads, caches, compiled code)."""
    per_sample: float
    """Per training sample (inputs, targets, the validation split, predictions)."""
    per_activation: float
    """Per batch sample per hidden unit (activations, their gradients, optimiser buffers)."""
    per_parameter: float
    """Per network parameter (weights, gradients, Adam's two moments, initial weights)."""


#: Measured figures per backend module (see the module's documentation for how).
BACKENDS: dict[str, BackendMemory] = {
    "torch": BackendMemory(imported=194 * _MB, working=46 * _MB, per_sample=147.0,
                           per_activation=58.0, per_parameter=36.0),
    "jax": BackendMemory(imported=148 * _MB, working=140 * _MB, per_sample=283.0,
                         per_activation=50.0, per_parameter=30.0),
}


def backend_of(modules: Iterable[str]) -> str | None:
    """The backend of :data:`BACKENDS` among the modules a model needs, or None."""
    needed = set(modules)
    return next((name for name in BACKENDS if name in needed), None)


def imported(module: str) -> bool:
    """Whether ``module`` is imported in this process already (nothing is imported)."""
    return module in sys.modules


class ModelCatalogue:
    """The field models a registry holds, as the estimate reads them without importing
    them: called with a model's name, the modules it needs (a :data:`ModelRequires`);
    :meth:`parameters`, the parameters of the networks it trains."""

    def __init__(self, registry: Registry) -> None:
        self._registry = registry

    def __call__(self, name: str) -> tuple[str, ...]:
        spec = self._spec(name)
        return () if spec is None else tuple(module for module, _ in spec.requires)

    def _spec(self, name: str) -> PluginSpec | None:
        if name not in self._registry.names(PluginKind.FIELD_MODEL):
            return None
        return self._registry.get(PluginKind.FIELD_MODEL, name)

    def _config(self, name: str, options: Mapping[str, object]) -> object | None:
        """The config of model ``name`` with ``options`` (None: unknown, or a model whose
        config class would be known only by importing its factory)."""
        spec = self._spec(name)
        if spec is None or spec.config is None:
            return None
        try:
            return spec.make_config({k: v for k, v in options.items() if k != "name"})
        except NlosfwError:
            return None

    def parameters(self, name: str, options: Mapping[str, object], shape: FieldShape
                   ) -> int | None:
        """The parameters of the networks model ``name`` with ``options`` trains on a field
        of ``shape`` (one network per frequency in ``single`` mode), from their configs'
        :meth:`~nlosfw.model.NeuralFieldConfig.network_shapes`; None when unknown."""
        from nlosfw.model.neural import FieldMode, NeuralFieldConfig

        config = self._config(name, options)
        if config is not None and not isinstance(config, NeuralFieldConfig):
            backend = backend_of(self(name))
            network = _network_options(config)
            if backend is None or network is None:
                return None
            config = self._config(f"{network[0]}_{backend}", network[1])
        if not isinstance(config, NeuralFieldConfig):
            return None
        mode = FieldMode(config.mode)
        try:
            arrays = config.network_shapes(replace(shape, mode=mode))
        except NlosfwError:
            return None
        networks = (shape.n_frequencies or 1) if mode == FieldMode.single else 1
        return networks * sum(math.prod(size) for size in arrays.values())


def _network_options(config: object) -> tuple[str, dict[str, object]] | None:
    """(name, options) of the registered network a model's config names (``network``,
    ``network_hidden`` and ``network_options``, a mapping or a method returning one)."""
    name = getattr(config, "network", None)
    if not isinstance(name, str):
        return None
    extra = getattr(config, "network_options", None) or {}
    extra = extra() if callable(extra) else extra
    hidden = getattr(config, "network_hidden", None)
    return name, {**({"hidden": list(hidden)} if hidden else {}), **dict(extra)}


def plugin_requires(host: PluginHost) -> ModelCatalogue:
    """The :class:`ModelCatalogue` of the field models ``host`` registers (their declared
    requirements and configs; no plugin is imported)."""
    return ModelCatalogue(host.registry)


def _int(value: object, default: int) -> int:
    try:
        return int(value)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        return default


def training_bytes(options: Mapping[str, object], backend: str, samples: float
                   ) -> tuple[float, float]:
    """(data, activations): the bytes a model of ``options`` on ``backend`` holds while
    training on ``samples`` samples (see the module's table)."""
    figures = BACKENDS[backend]
    hidden = options.get("hidden", options.get("network_hidden")) or ()
    widths = sum(_int(w, 0) for w in hidden) if isinstance(hidden, Iterable) else 0
    widths += 2 * max(0, _int(options.get("features"), 0))
    batch = _int(options.get("batch_size", options.get("network_batch_size")), 0)
    batch = min(batch, int(samples)) if batch > 0 else int(samples)
    return figures.per_sample * samples, figures.per_activation * batch * widths


def parameter_bytes(parameters: int, backend: str) -> float:
    """The bytes ``parameters`` network parameters take while they train on ``backend``."""
    return BACKENDS[backend].per_parameter * parameters


def runtime_bytes(backends: Iterable[str]) -> float:
    """The runtimes of ``backends`` (each counted once): import (unless done) + working."""
    return sum(BACKENDS[b].working + (0.0 if imported(b) else BACKENDS[b].imported)
               for b in set(backends))
