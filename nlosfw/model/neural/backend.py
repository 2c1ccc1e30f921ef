"""The backend half of a neural field: a network (or a batch of them) and Adam on one device.

The shared trainer (:mod:`nlosfw.model.neural.trainer`) builds a network through a
:class:`NetworkBuild` and hands it to its backend plugin's :class:`Backend` subclass (one
for "a torch module", one for "a JAX module"; they live in the torch and JAX plugins).
What is backend-independent is implemented here once: choosing the initial state,
checking a stored state against the network, chunked validation and prediction,
and checking what the network returns.

State. A network's state is a mapping name -> numpy array (its trainable
parameters and its fixed arrays, e.g. a random Fourier matrix), the portable form
in which it is saved. Names are the backend's own dotted paths (``layers.0.weight``).

Data layout. Multi mode (``n_networks`` 0): inputs ``x`` (N, in_dim), targets ``y``
(N, 2). Single mode (``n_networks`` K > 0): K independent copies of the network,
every state array with a leading axis K; inputs ``x`` (P, in_dim) shared by the K
networks, targets ``y`` (K, P, 2). Batch indices always index the N (or P) axis.
The loss is the mean squared error over every element of the batch (and network),
plus, when the trainer passes a :class:`SmoothnessBatch`, its weighted penalty.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from nlosfw.common.errors import DataError, FitError
from nlosfw.model.neural.config import FieldShape, NeuralFieldConfig

#: Rows per forward pass when predicting or validating (bounds memory).
PREDICT_CHUNK = 1 << 16


@dataclass(frozen=True)
class SmoothnessBatch:
    """One step's regularisation across frequency (:mod:`nlosfw.model.neural.smoothness`).

    The backend evaluates the network at ``x`` and adds ``weight * mean((D @ out)^2)`` to the
    loss, ``out`` being the outputs as (A, M, 2): in multi mode ``x`` is (A * M, in_dim)
    frequency-major (A frequencies at the same M points) and the outputs are reshaped;
    in single mode ``x`` is (M, in_dim) and the K = A networks give (K, M, 2).
    """

    x: np.ndarray
    matrix: np.ndarray
    """D, (B, A) float32: each row a second difference across the A frequencies."""
    weight: float


@dataclass(frozen=True)
class NetworkBuild:
    """What a backend builds: ``factory(config, shape)`` (JAX: ``factory(config, shape, key)``).

    A network may define ``initial_state(n_networks, seed) -> {name: numpy array}`` to
    start from weights that do not depend on the backend (with a leading axis
    ``n_networks`` when it is > 0); arrays it does not return keep the backend's own
    initialisation, drawn from ``config.seed``.
    """

    factory: Callable[..., Any]
    config: NeuralFieldConfig
    shape: FieldShape
    n_networks: int = 0
    """0: one network; K > 0: K independent networks trained as a batch (single mode)."""
    who: str = "network"
    """Names the model (or file) in error messages."""


#: A backend's network (a ``torch.nn.Module``, a JAX pytree of arrays, ...).
NetT = TypeVar("NetT")
#: A backend's loss handle (a device scalar read back only when needed).
LossT = TypeVar("LossT")
#: A backend's copy of the trainable state (see :meth:`Backend.snapshot`).
SnapT = TypeVar("SnapT")


class DeviceArray(Protocol):
    """An array of a backend on its device: all the shared code needs is its shape."""

    @property
    def shape(self) -> Sequence[int]: ...


ArrT = TypeVar("ArrT", bound=DeviceArray)


class Backend(ABC, Generic[NetT, ArrT, LossT, SnapT]):
    """A network's state and Adam's on one device, with training steps and forward passes.

    A backend implements the methods marked abstract; each takes and returns numpy
    arrays at its boundary, so the trainer never sees a tensor. Its type parameters are the
    backend's network, device array, loss handle and state snapshot.
    """

    def __init__(self, build: NetworkBuild, state: Mapping[str, np.ndarray] | None = None
                 ) -> None:
        """Build the network and place it on the device, from ``state`` (a loaded file)
        or else from its initial state."""
        self.build = build
        self.n_networks = build.n_networks
        self.x: ArrT | None = None
        self.y: ArrT | None = None
        self.val_x: ArrT | None = None
        self.val_y: ArrT | None = None
        template = self.make_network(0)
        own = self.network_state(template)
        trainable = self.trainable(template)
        self.trainable_names = [n for n in own if n in trainable]
        self.parameters_per_network = sum(int(own[n].size) for n in self.trainable_names)
        if state is None:
            state = self._initial_state(template, own)
        self.place(template, self._checked(state, own))
        self._check_outputs()

    @classmethod
    def check_device(cls, name: str) -> None:
        """A one-line ConfigError for ``model.device`` when this backend cannot use device
        ``name`` on this machine; called before a run, so it must not start training or
        hold the device (a sweep's workers need it). Default: every name is accepted here
        (the engine refuses it when it starts)."""

    # ------------------------------------------------------------------ backend: building
    @abstractmethod
    def make_network(self, index: int) -> NetT:
        """Network number ``index`` built by the factory, with its own seeded initialisation
        (different networks for different indices, the same for the same seed)."""

    @abstractmethod
    def network_state(self, network: NetT) -> dict[str, np.ndarray]:
        """Every array of ``network`` (trainable and fixed) by name, as numpy copies."""

    @abstractmethod
    def trainable(self, network: NetT) -> set[str]:
        """Names of the arrays Adam trains (the others stay fixed)."""

    @abstractmethod
    def place(self, network: NetT, state: Mapping[str, np.ndarray]) -> None:
        """Put ``network`` with ``state`` (leading axis K in single mode) on the device and
        create Adam's state for its trainable arrays."""

    # ------------------------------------------------------------------ backend: training
    @abstractmethod
    def to_device(self, a: np.ndarray) -> ArrT:
        """``a`` as an array of the backend on the device (floating point as float32)."""

    @abstractmethod
    def step(self, idx: np.ndarray | None, lr: float, smooth: SmoothnessBatch | None = None
             ) -> LossT:
        """One Adam step on the batch ``idx`` (None: all data), with the penalty of ``smooth``
        added to the loss; returns a handle of the data loss (the mean squared error)."""

    @abstractmethod
    def mean_loss(self, handles: list[LossT]) -> float:
        """Mean of the losses behind ``handles`` (synchronises with the device)."""

    @abstractmethod
    def squared_error(self, start: int, stop: int) -> tuple[float, int]:
        """(Sum of squared errors, number of values) on validation rows ``start:stop``."""


    @abstractmethod
    def snapshot(self) -> SnapT:
        """A copy of the current trainable state that :meth:`restore` can bring back."""

    @abstractmethod
    def restore(self, snapshot: SnapT) -> None:
        """Bring back the state saved by :meth:`snapshot`."""

    @abstractmethod
    def state(self) -> dict[str, np.ndarray]:
        """The current state (every array, by name) as numpy arrays."""

    @abstractmethod
    def evaluate(self, x: np.ndarray, networks: np.ndarray | None) -> np.ndarray:
        """Outputs (n, 2) float32 of one chunk of inputs ``x`` (n, in_dim), or
        (len(networks), n, 2) of the single-mode networks ``networks`` (all when None)."""

    # ------------------------------------------------------------------ shared
    def set_data(self, x: np.ndarray, y: np.ndarray, val_x: np.ndarray | None,
                 val_y: np.ndarray | None) -> None:
        """Move training (and validation) arrays to the device."""
        self.x, self.y = self.to_device(x), self.to_device(y)
        self.val_x = None if val_x is None else self.to_device(val_x)
        self.val_y = None if val_y is None else self.to_device(val_y)

    def training_data(self) -> tuple[ArrT, ArrT]:
        """The training inputs and targets on the device (set by :meth:`set_data`)."""
        if self.x is None or self.y is None:
            raise FitError(f"{self.build.who}: no training data; call set_data() first")
        return self.x, self.y

    def validation_data(self) -> tuple[ArrT, ArrT]:
        """The validation inputs and targets on the device (see :meth:`n_validation`)."""
        if self.val_x is None or self.val_y is None:
            raise FitError(f"{self.build.who}: no validation data")
        return self.val_x, self.val_y

    def n_validation(self) -> int:
        """Rows of validation data (0: none)."""
        return 0 if self.val_x is None else int(self.val_x.shape[0])

    def val_loss(self) -> float:
        """Mean squared error on the validation data."""
        total, count = 0.0, 0
        for start in range(0, self.n_validation(), PREDICT_CHUNK):
            err, n = self.squared_error(start, start + PREDICT_CHUNK)
            total, count = total + err, count + n
        return total / max(count, 1)

    def parameters(self) -> list[np.ndarray]:
        """The trainable arrays, in the network's order."""
        state = self.state()
        return [state[n] for n in self.trainable_names]

    def forward(self, x: np.ndarray, networks: np.ndarray | None = None) -> np.ndarray:
        """Outputs (N, 2) of the network, or (len(networks), N, 2) of some single-mode ones.

        Rows go in chunks of one power-of-two size (the last one padded), so a backend
        that compiles per shape compiles once per size.
        """
        n = x.shape[0]
        lead = (len(networks) if networks is not None else self.n_networks,) \
            if self.n_networks else ()
        if n == 0:
            return np.zeros((*lead, 0, 2), dtype=np.float32)
        chunk = min(PREDICT_CHUNK, 1 << max(0, math.ceil(math.log2(n))))
        pad = (-n) % chunk
        xp = np.concatenate([x, np.zeros((pad, x.shape[1]), dtype=x.dtype)]) if pad else x
        sel = None if networks is None else np.asarray(networks, dtype=np.int64)
        outs = [self.evaluate(np.ascontiguousarray(xp[k:k + chunk], dtype=np.float32), sel)
                for k in range(0, xp.shape[0], chunk)]
        return np.concatenate(outs, axis=-2)[..., :n, :]

    def _initial_state(self, template: NetT, own: dict[str, np.ndarray]
                       ) -> dict[str, np.ndarray]:
        declared = getattr(template, "initial_state", None)
        fixed = dict(declared(self.n_networks, self.build.config.seed)) if declared else {}
        if set(own) <= set(fixed) or not self.n_networks:
            return {**own, **fixed}
        copies = [own, *(self.network_state(self.make_network(k))
                         for k in range(1, self.n_networks))]
        return {name: np.stack([c[name] for c in copies]) for name in own} | fixed

    def _checked(self, state: Mapping[str, np.ndarray], own: Mapping[str, np.ndarray]
                 ) -> dict[str, np.ndarray]:
        who = self.build.who
        if set(state) != set(own):
            missing = sorted(set(own) - set(state))
            extra = sorted(set(state) - set(own))
            raise DataError(f"{who}: the state does not fit the network (missing "
                            f"{missing[:4] or 'none'}, unexpected {extra[:4] or 'none'})")
        lead = (self.n_networks,) if self.n_networks else ()
        out = {}
        for name, ref in own.items():
            value = np.asarray(state[name])
            if value.shape != lead + ref.shape or not np.all(np.isfinite(value)):
                raise DataError(f"{who}: array {name} has shape {value.shape}, the network "
                                f"needs {lead + ref.shape} (finite)")
            out[name] = value.astype(ref.dtype)
        return out

    def _check_outputs(self) -> None:
        x = np.zeros((3, self.build.shape.in_dim), dtype=np.float32)
        out = self.forward(x)
        lead = (self.n_networks,) if self.n_networks else ()
        if out.shape != lead + (3, 2):
            raise FitError(f"{self.build.who}: the network maps (3, {x.shape[1]}) inputs to "
                           f"shape {out.shape[len(lead):]}; it must return (N, 2) = (Re, Im) "
                           "or a complex (N,)")
