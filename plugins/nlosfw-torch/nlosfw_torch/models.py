"""PyTorch engines of the neural field models (see :mod:`nlosfw.model.trainer`).

The training loop, initial weights, batches and files are shared with the JAX
backend; this module only runs Adam steps and forward passes with torch.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import torch

from nlosfw.common import ConfigError, one_line
from nlosfw.model import (
    PREDICT_CHUNK,
    Architecture,
    Engine,
    NeuralFieldModel,
    PEFieldConfig,
    SirenFieldConfig,
    TanhFieldConfig,
)

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


class TorchEngine(Engine):
    """Parameters, Adam state and data as torch tensors on one device (float32)."""

    def __init__(self, arch: Architecture, params: list[np.ndarray], n_networks: int,
                 device: str, threads: int) -> None:
        super().__init__(arch, params, n_networks, device, threads)
        self.threads = threads
        self.device = resolve_device(device)
        self.params = [torch.tensor(p, dtype=torch.float32, device=self.device,
                                    requires_grad=True) for p in params]
        self.opt = torch.optim.Adam(self.params, lr=1e-3, betas=(0.9, 0.999), eps=1e-8)
        self.x = self.y = self.val_x = self.val_y = None

    @contextmanager
    def _threads(self, predict: bool = False) -> Iterator[None]:
        """torch's CPU threads for one call, then restored: ``threads`` (if > 0) for
        training; torch's default (every core) for prediction, one large batch that does
        gain from threads (64 x 64 x 151 points: 0.27 s on 2 threads, 0.48 s on one)."""
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

    # ------------------------------------------------------------------ network
    def _net(self, params: list[torch.Tensor], x: torch.Tensor) -> torch.Tensor:
        arch, h = self.arch, x
        n_layers = len(params) // 2
        for i in range(n_layers):
            w, b = params[2 * i], params[2 * i + 1]
            if w.dim() == 3:          # single mode: a batch of networks
                z = torch.matmul(h, w) + b.unsqueeze(-2)
            else:
                z = torch.addmm(b, h, w)
            if i == n_layers - 1:
                return z
            if arch.activation == "sine":
                h = torch.sin(z * (arch.omega0_first if i == 0 else arch.omega0_hidden))
            elif arch.activation == "relu":
                h = torch.relu(z)
            else:
                h = torch.tanh(z)
        return h

    def _tensor(self, a: np.ndarray | None) -> torch.Tensor | None:
        if a is None:
            return None
        return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(self.device)

    # ------------------------------------------------------------------ training
    def set_data(self, x: np.ndarray, y: np.ndarray, val_x: np.ndarray | None,
                 val_y: np.ndarray | None) -> None:
        self.x, self.y = self._tensor(x), self._tensor(y)
        self.val_x, self.val_y = self._tensor(val_x), self._tensor(val_y)

    def step(self, idx: np.ndarray | None, lr: float) -> Any:
        with self._threads():
            return self._step(idx, lr)

    def _step(self, idx: np.ndarray | None, lr: float) -> Any:
        x, y = self.x, self.y
        if idx is not None:
            index = torch.from_numpy(idx).to(self.device)
            x = x.index_select(0, index)
            y = y.index_select(-2, index)
        for group in self.opt.param_groups:
            group["lr"] = lr
        self.opt.zero_grad(set_to_none=True)
        loss = torch.mean(torch.square(self._net(self.params, x) - y))
        loss.backward()
        self.opt.step()
        return loss.detach()

    def mean_loss(self, handles: list[Any]) -> float:
        return float(torch.stack(handles).mean().item())

    def val_loss(self) -> float:
        total, count = 0.0, 0
        with self._threads(), torch.no_grad():
            for k in range(0, self.val_x.shape[0], PREDICT_CHUNK):
                x = self.val_x[k:k + PREDICT_CHUNK]
                y = self.val_y[..., k:k + PREDICT_CHUNK, :]
                total += float(torch.sum(torch.square(self._net(self.params, x) - y)).item())
                count += y.numel()
        return total / max(count, 1)

    def snapshot(self) -> Any:
        return [p.detach().clone() for p in self.params]

    def restore(self, snapshot: Any) -> None:
        with torch.no_grad():
            for p, s in zip(self.params, snapshot, strict=True):
                p.copy_(s)

    def parameters(self) -> list[np.ndarray]:
        return [p.detach().cpu().numpy().astype(np.float32) for p in self.params]

    # ------------------------------------------------------------------ prediction
    def forward(self, x: np.ndarray, networks: np.ndarray | None = None) -> np.ndarray:
        params = self.params
        if networks is not None:
            sel = torch.from_numpy(np.asarray(networks, dtype=np.int64)).to(self.device)
            params = [p.detach().index_select(0, sel) for p in params]
        lead = (len(params[0]),) if params[0].dim() == 3 else ()
        if x.shape[0] == 0:
            return np.zeros((*lead, 0, 2), dtype=np.float32)
        outs = []
        with self._threads(predict=True), torch.inference_mode():
            xt = self._tensor(x)
            for k in range(0, xt.shape[0], PREDICT_CHUNK):
                outs.append(self._net(params, xt[k:k + PREDICT_CHUNK]).cpu())
        return torch.cat(outs, dim=-2).numpy()


class _TorchModel(NeuralFieldModel):
    backend = "torch"

    def make_engine(self, arch: Architecture, params: list[np.ndarray],
                    n_networks: int) -> Engine:
        return TorchEngine(arch, params, n_networks, self.config.device, self.config.threads)


class TanhTorch(_TorchModel):
    """MLP with tanh activations (thesis F_w,M), in PyTorch."""

    config_class = TanhFieldConfig
    family = "tanh"


class PETorch(_TorchModel):
    """MLP on NeRF's positional encoding (thesis F_w,P and F_P), in PyTorch."""

    config_class = PEFieldConfig
    family = "pe"


class SirenTorch(_TorchModel):
    """SIREN (thesis F_S), in PyTorch."""

    config_class = SirenFieldConfig
    family = "siren"
