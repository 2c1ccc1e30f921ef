"""The torch backend: runs any ``torch.nn.Module`` under the shared trainer.

The module maps normalised inputs (N, in_dim) float32 to (N, 2) = (Re, Im) or to a
complex (N,). Its trainable arrays are its parameters with ``requires_grad``; its
buffers (and frozen parameters) are fixed arrays, saved with it. Single mode
trains K copies at once: their states are stacked on a leading axis and the
module is evaluated with :func:`torch.func.functional_call` under
:func:`torch.vmap`. Everything else (batches, schedule, validation, files) is the
shared trainer's (:mod:`nlosfw.model`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np
import torch

from nlosfw.common import ConfigError, FitError, one_line
from nlosfw.model.neural import Backend, NetworkBuild, SmoothnessBatch

#: torch's own CPU thread count (one per core), read before any model changes it.
DEFAULT_THREADS = torch.get_num_threads()


def resolve_device(name: str) -> torch.device:
    """``auto`` -> the first CUDA (or MPS) device when present, else the CPU."""
    if name == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda")
        mps = getattr(torch.backends, "mps", None)
        if mps is not None and mps.is_available():
            return torch.device("mps")
        return torch.device("cpu")
    try:
        device = torch.device(name)
        torch.empty(1, device=device)
    except (RuntimeError, AssertionError) as err:
        raise ConfigError("model.device", f"torch cannot use device {name!r} "
                          f"({one_line(err)}); "
                          "valid: auto, cpu, cuda, cuda:N") from None
    return device


def check_device(name: str) -> None:
    """A ConfigError for ``model.device`` unless torch can use device ``name`` on this
    machine, checked without using it: a CUDA device must be one torch counts (no CUDA
    context is created, nothing allocated), the CPU always is; another kind (mps, ...) is
    tried as :func:`resolve_device` tries it."""
    if name == "auto":
        return
    try:
        device = torch.device(name)
    except (RuntimeError, ValueError) as err:
        raise ConfigError("model.device", f"torch does not know device {name!r} "
                          f"({one_line(err)}); valid: auto, cpu, cuda, cuda:N") from None
    if device.type == "cpu":
        return
    if device.type != "cuda":
        resolve_device(name)
        return
    count = torch.cuda.device_count()
    if (device.index or 0) >= count:
        valid = f"auto, cpu, cuda, cuda:0 to cuda:{count - 1}" if count else "auto, cpu"
        raise ConfigError("model.device", f"torch cannot use device {name!r}: it sees "
                          f"{count or 'no'} CUDA device{'' if count == 1 else 's'} on this "
                          f"machine; valid: {valid}")


class TorchBackend(Backend):
    """A torch module's state and Adam's on one device (float32)."""

    @classmethod
    def check_device(cls, name: str) -> None:
        check_device(name)

    def __init__(self, build: NetworkBuild, state: Mapping[str, np.ndarray] | None = None
                 ) -> None:
        self.threads = build.config.threads
        self.device = resolve_device(build.config.device)
        self.fixed_x: Any = None
        self.fixed_val_x: Any = None
        super().__init__(build, state)

    # ------------------------------------------------------------------ building
    def make_network(self, index: int) -> torch.nn.Module:
        seed = int(np.random.SeedSequence([self.build.config.seed, index]).generate_state(1)[0])
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            network = self.build.factory(self.build.config, self.build.shape)
        if not isinstance(network, torch.nn.Module):
            raise FitError(f"{self.build.who}: the network factory returned "
                           f"{type(network).__name__}, not a torch.nn.Module")
        return network

    def network_state(self, network: Any) -> dict[str, np.ndarray]:
        return {name: t.detach().cpu().numpy().copy()
                for name, t in network.state_dict().items()}

    def trainable(self, network: Any) -> set[str]:
        return {name for name, p in network.named_parameters() if p.requires_grad}

    def place(self, network: Any, state: Mapping[str, np.ndarray]) -> None:
        self.network = network.to(self.device)
        self.names = list(state)
        tensors = {k: torch.tensor(v, device=self.device) for k, v in state.items()}
        self.params = {k: tensors[k].requires_grad_(True) for k in self.trainable_names}
        self.fixed = {k: v for k, v in tensors.items() if k not in self.params}
        self.opt = torch.optim.Adam(list(self.params.values()), lr=1e-3, betas=(0.9, 0.999),
                                    eps=1e-8)

    # ------------------------------------------------------------------ network
    def _apply(self, state: Mapping[str, torch.Tensor], x: Any) -> torch.Tensor:
        """(N, 2) outputs, or (K, N, 2) of K stacked networks (single mode), for inputs
        ``x`` (N, D) or what the network precomputed from them."""
        def call(s: Mapping[str, torch.Tensor]) -> torch.Tensor:
            out = torch.func.functional_call(self.network, dict(s), (x,))
            return torch.view_as_real(out) if out.is_complex() else out

        if self.n_networks:
            return torch.vmap(call)(dict(state))
        return call(state)

    @contextmanager
    def _threads(self, predict: bool = False) -> Iterator[None]:
        """torch's CPU threads for one call, then restored: ``threads`` (if > 0) for
        training; torch's default (every core) for prediction, one large batch that does
        gain from threads (a 64 x 64 x 151 field predicts faster on two threads than one)."""
        before = torch.get_num_threads()
        wanted = DEFAULT_THREADS if predict else self.threads
        if wanted <= 0 or before == wanted:
            yield
            return
        torch.set_num_threads(wanted)
        try:
            yield
        finally:
            torch.set_num_threads(before)

    # ------------------------------------------------------------------ training
    def to_device(self, a: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(self.device)

    def set_data(self, x: np.ndarray, y: np.ndarray, val_x: np.ndarray | None,
                 val_y: np.ndarray | None) -> None:
        """As :meth:`Backend.set_data`; a network with ``precompute_inputs(x)`` (what its
        forward can take instead of inputs it sees again and again, or None) gets that
        in place of the training and validation inputs."""
        super().set_data(x, y, val_x, val_y)
        precompute = getattr(self.network, "precompute_inputs", None)
        if precompute is not None:
            with self._threads():
                self.fixed_x = precompute(self.x)
                self.fixed_val_x = None if self.val_x is None else precompute(self.val_x)

    def step(self, idx: np.ndarray | None, lr: float, smooth: SmoothnessBatch | None = None
             ) -> Any:
        x, y = self.training_data()
        inputs: Any = x if self.fixed_x is None else self.fixed_x
        state = {**self.fixed, **self.params}
        with self._threads():
            if idx is not None:
                index = torch.from_numpy(idx).to(self.device)
                y = y.index_select(-2, index)
                inputs = (x.index_select(0, index) if self.fixed_x is None
                          else self.fixed_x.select(index))
            for group in self.opt.param_groups:
                group["lr"] = lr
            self.opt.zero_grad(set_to_none=True)
            loss = torch.mean(torch.square(self._apply(state, inputs) - y))
            total = loss
            if smooth is not None:
                matrix = self.to_device(smooth.matrix)
                out = self._apply(state, self.to_device(smooth.x))
                curvature = torch.tensordot(matrix, out.reshape(matrix.shape[1], -1, 2), 1)
                total = loss + smooth.weight * torch.mean(torch.square(curvature))
            total.backward()
            self.opt.step()
        return loss.detach()

    def mean_loss(self, handles: list[Any]) -> float:
        return float(torch.stack(handles).mean().item())

    def squared_error(self, start: int, stop: int) -> tuple[float, int]:
        val_x, val_y = self.validation_data()
        x = val_x[start:stop] if self.fixed_val_x is None else self.fixed_val_x.part(start, stop)
        y = val_y[..., start:stop, :]
        with self._threads(), torch.no_grad():
            out = self._apply({**self.fixed, **self.params}, x)
            return float(torch.sum(torch.square(out - y)).item()), int(y.numel())

    def snapshot(self) -> Any:
        return {k: p.detach().clone() for k, p in self.params.items()}

    def restore(self, snapshot: Any) -> None:
        with torch.no_grad():
            for k, p in self.params.items():
                p.copy_(snapshot[k])

    def state(self) -> dict[str, np.ndarray]:
        tensors = {**self.fixed, **self.params}
        return {k: tensors[k].detach().cpu().numpy().copy() for k in self.names}

    # ------------------------------------------------------------------ prediction
    def evaluate(self, x: np.ndarray, networks: np.ndarray | None) -> np.ndarray:
        state = {**self.fixed, **self.params}
        with self._threads(predict=True), torch.inference_mode():
            if networks is not None:
                sel = torch.from_numpy(networks).to(self.device)
                state = {k: v.index_select(0, sel) for k, v in state.items()}
            out = self._apply(state, self.to_device(x))
            return out.float().cpu().numpy()
