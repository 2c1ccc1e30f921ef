"""``neural_volume_torch``: a registered torch network's non-negative albedo on rsd_prior's
lattice, propagated to the wall by RSD in torch
(:class:`nlosfw.model.hybrid.NeuralVolumeFieldModel`).

:class:`TorchPlaneOperator` is ``SceneOperator.forward`` in torch (differentiable,
``torch.fft``), from the numpy constants of :func:`nlosfw.model.hybrid.plane_stack`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any, cast

import torch
from torch.utils.checkpoint import checkpoint

from nlosfw.common import FitError
from nlosfw.model import TrainingStep
from nlosfw.model.hybrid import (
    BestStep,
    FoldedSpectra,
    NeuralVolumeConfig,
    NeuralVolumeFieldModel,
    PlaneStack,
    TrainedVolume,
    VolumeProblem,
    fold_spectra,
    history_entry,
)
from nlosfw.model.neural import NetworkBuild, NeuralFieldModel
from nlosfw.plugins import registered_network
from nlosfw_torch.backend import TorchBackend, resolve_device

#: Steps between entries of the fit history.
HISTORY_EVERY = 10

#: Voxels per piece of the network's pass on the CPU (see :func:`volume_albedo`). For
#: SIRENs of two hidden layers 64, 128 and 256 wide over 295 750 voxels (one thread), 4096
#: was within 9 % of the fastest of 1024 to 8192, and 1.4 to 2 times faster than one pass.
CPU_CHUNK = 4096


class _SpectraProduct(torch.autograd.Function):
    """S c for constant spectra S (L, F, Z) and columns c (L, Z, M), with the gradient
    S^H g computed as (g^H S)^H, which reads S as it is stored. Autograd's own backward of
    ``bmm`` multiplies by S's conjugate transpose, several times the forward's time
    (``benchmarks/model/bench_volume_operator.py`` compares the two, with the same gradient; its
    numbers: ``studies/sparse_scans_measured/README.md``)."""

    @staticmethod
    def forward(ctx: Any, spectra: torch.Tensor, columns: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(spectra)
        return torch.bmm(spectra, columns)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[None, torch.Tensor]:
        (spectra,) = ctx.saved_tensors
        return None, torch.bmm(grad.conj().transpose(1, 2), spectra).conj().transpose(1, 2)


class TorchPlaneOperator:
    """A a for an albedo a (Z, Y, X), real: the wall fields (F, ny, nx), complex, on
    ``device`` (see :class:`nlosfw.model.hybrid.PlaneStack`).

    A confocal scan on the CPU sums over planes as one batched matrix product per lattice
    point (the spectra reordered once as (Ly Lx, F, Z), a copy as large as the product the
    other path makes in every step; its gradient by :class:`_SpectraProduct`): faster there
    than the product summed over planes. A GPU and the single-spot case keep that sum
    (each plane's laser leg makes the inputs differ per frequency there).

    Where the confocal spectra have the symmetry of :func:`nlosfw.model.hybrid.fold_spectra`
    (``rsd_prior``'s lattices around a regular grid of kept points do), the product is one
    per orbit of up to 8 lattice points instead of one per point (``fold=False``: per
    point), holding several times less than the reordered spectra
    (``benchmarks/model/bench_volume_operator.py``; its numbers:
    ``studies/sparse_scans_measured/README.md``).
    """

    def __init__(self, stack: PlaneStack, device: torch.device | str = "cpu",
                 fold: bool = True) -> None:
        self.laser = None if stack.laser is None else torch.from_numpy(stack.laser).to(device)
        self.shape, self.inputs, self.outputs = stack.shape, stack.inputs, stack.outputs
        self.batched = self.laser is None and torch.device(device).type == "cpu"
        self.folded: FoldedSpectra | None = (fold_spectra(stack) if self.batched and fold
                                              else None)
        z, n_f = stack.spectra.shape[:2]
        if self.folded is not None:                     # one spectrum per orbit (U, F, Z)
            self.spectra = torch.from_numpy(self.folded.spectra)
            self.members = torch.from_numpy(self.folded.members)
            self.slots = torch.from_numpy(self.folded.slots)
            self.phase = torch.from_numpy(self.folded.phase)[:, None]
        elif self.batched:
            self.spectra = torch.from_numpy(stack.spectra).permute(2, 3, 1, 0).reshape(
                -1, n_f, z).contiguous()
        else:
            self.spectra = torch.from_numpy(stack.spectra).to(device)
        self.dtype = self.spectra.dtype

    def __call__(self, albedo: torch.Tensor) -> torch.Tensor:
        a = albedo.to(self.dtype)[:, None]                          # (Z, 1, Y, X)
        source = a if self.laser is None else a * self.laser        # (Z, 1 or F, Y, X)
        work = torch.zeros(source.shape[:2] + self.shape, dtype=source.dtype,
                           device=source.device)
        work[(..., self.inputs[0], self.inputs[1])] = source
        planes = torch.fft.fft2(work)                               # (Z, 1 or F, Ly, Lx)
        if self.folded is not None:
            total = self._folded_product(planes[:, 0])
        elif self.batched:                                          # (Ly Lx, F, Z) @ (.., Z, 1)
            columns = planes[:, 0].permute(1, 2, 0).reshape(-1, planes.shape[0], 1)
            product = cast(torch.Tensor, _SpectraProduct.apply(self.spectra, columns))
            total = product.reshape(self.shape + (-1,)).permute(2, 0, 1)
        else:
            total = torch.sum(self.spectra * planes, dim=0)         # (F, Ly, Lx)
        return torch.fft.ifft2(total)[(..., self.outputs[0], self.outputs[1])]

    def _folded_product(self, planes: torch.Tensor) -> torch.Tensor:
        """K c per lattice point from the orbits' spectra: planes (Z, Ly, Lx) -> (F, Ly, Lx)."""
        z = planes.shape[0]
        columns = planes.permute(1, 2, 0).reshape(-1, z)            # (Ly Lx, Z)
        columns = torch.cat([columns, columns.new_zeros(1, z)])     # + the padding column
        grouped = columns[self.members].transpose(1, 2)             # (U, Z, M)
        product = cast(torch.Tensor, _SpectraProduct.apply(self.spectra, grouped))
        per_point = product.transpose(1, 2).reshape(-1, product.shape[1])[self.slots]
        return (per_point * self.phase).reshape(self.shape + (-1,)).permute(2, 0, 1)


def _real_output(out: torch.Tensor) -> torch.Tensor:
    """The network's first output channel (the real part of a complex output)."""
    return out.real if out.is_complex() else out[..., 0]


def volume_albedo(network: Callable[[torch.Tensor], torch.Tensor], coords: torch.Tensor,
                  gain: torch.Tensor, shift: float, chunk: int | None = None) -> torch.Tensor:
    """gain * softplus(network(coords) + shift), shaped as ``gain``.

    With ``chunk``, the network runs on ``chunk`` voxels at a time and keeps none of its
    activations: each piece is run again in the backward pass (``torch.utils.checkpoint``),
    so every piece's activations stay in the CPU's cache. The network must treat its
    points independently (every registered network does). The gradient is the same;
    the time in pieces against whole (``benchmarks/model/bench_volume_network.py``):
    ``studies/sparse_scans_measured/README.md``."""
    def values(x: torch.Tensor) -> torch.Tensor:
        return torch.nn.functional.softplus(_real_output(network(x)) + shift)

    if chunk is None or coords.shape[0] <= chunk:
        out = values(coords)
    else:
        out = torch.cat([cast(torch.Tensor, checkpoint(values, piece, use_reentrant=False))
                         for piece in coords.split(chunk)])
    return gain * out.reshape(gain.shape)


def total_variation(albedo: torch.Tensor) -> torch.Tensor:
    """:func:`nlosfw.model.hybrid.albedo_total_variation` of ``albedo`` (Z, Y, X), its
    sum held constant (no gradient flows through it)."""
    total = torch.clamp_min(albedo.detach().sum(), torch.finfo(albedo.dtype).tiny)
    return (torch.abs(torch.diff(albedo, dim=2)).sum()
            + torch.abs(torch.diff(albedo, dim=1)).sum()) / total


class NeuralVolumeTorch(NeuralVolumeFieldModel):
    """A torch network's albedo propagated by RSD; on a GPU when torch sees one."""

    backend = "torch"

    @classmethod
    def network_class(cls, name: str) -> type[NeuralFieldModel]:
        """The registered torch network ``name``'s field-model class."""
        return registered_network(name, "torch")

    @classmethod
    def use_threads(cls, threads: int) -> None:
        """torch's CPU threads in the calling thread (its training restores its own at the
        end)."""
        torch.set_num_threads(threads)

    def stack_copies(self, confocal: bool) -> int:
        """Two on a confocal scan on the CPU (the operator's reordered spectra), else one
        (torch shares the numpy stack's memory on the CPU; a GPU holds its own)."""
        return 2 if confocal and resolve_device(self.config.device).type == "cpu" else 1

    @classmethod
    def held_stacks(cls, config: NeuralVolumeConfig, confocal: bool) -> float:
        """The stack, and on a confocal scan on the CPU its folded spectra (one spectrum per
        orbit of up to 8 lattice points: an eighth of it; :class:`TorchPlaneOperator`)."""
        return 1.125 if confocal and resolve_device(config.device).type == "cpu" else 1.0

    def train(self, problem: VolumeProblem,
              on_step: Callable[[TrainingStep], None] | None = None) -> TrainedVolume:
        """Adam on the relative squared error of the propagated albedo (full batch), plus
        ``problem.tv_weight_at`` the step times its :func:`total_variation`."""
        cfg, who = self.config, self.model_name()
        start = time.perf_counter()
        net = TorchBackend(NetworkBuild(problem.network.network_factory,
                                          problem.network_config, problem.network_shape,
                                          who=who))
        device = net.device
        op = TorchPlaneOperator(problem.stack, device)
        coords = torch.from_numpy(problem.coords).to(device)
        gain = torch.from_numpy(problem.gain).to(device)
        data = torch.from_numpy(problem.data).to(device)
        train = torch.from_numpy(problem.train).to(device)
        val = None if problem.validation is None else \
            torch.from_numpy(problem.validation).to(device)
        power = torch.abs(data) ** 2
        train_power = float(torch.sum(power * train).item())
        val_power = None if val is None else float(torch.sum(power * val).item())
        state = {**net.fixed, **net.params}
        opt = torch.optim.Adam(list(net.params.values()), lr=cfg.lr)
        chunk = CPU_CHUNK if device.type == "cpu" else None

        def network(x: torch.Tensor) -> torch.Tensor:
            return cast(torch.Tensor, torch.func.functional_call(net.network, state, (x,)))

        def albedo() -> torch.Tensor:
            return volume_albedo(network, coords, gain, problem.shift, chunk)

        def validation_error(squared: torch.Tensor) -> float | None:
            if val is None or val_power is None:
                return None
            return float(torch.sum(squared.detach() * val).item()) / val_power

        history: list[dict[str, float]] = []
        best = BestStep(cfg.patience, cfg.average_steps)
        before = torch.get_num_threads()
        if cfg.threads > 0:
            torch.set_num_threads(cfg.threads)
        try:
            loss_value = math.nan
            k = 0
            for k in range(cfg.steps):
                for group in opt.param_groups:
                    group["lr"] = self.learning_rate(k)
                opt.zero_grad(set_to_none=True)
                current = albedo()
                squared = torch.abs(op(current) - data) ** 2
                loss = torch.sum(squared * train) / train_power
                if problem.tv_weight > 0:
                    loss = loss + problem.tv_weight_at(k) * total_variation(current)
                error = validation_error(squared)
                best.offer(k, error, current.detach())
                loss.backward()
                opt.step()
                loss_value = float(loss.item())
                if not math.isfinite(loss_value):
                    raise FitError(f"{who}: training diverged at step {k + 1} (loss "
                                   f"{loss_value}); lower model.lr")
                if k == 0 or (k + 1) % HISTORY_EVERY == 0 or k + 1 == cfg.steps:
                    history.append(history_entry(k + 1, loss_value, error))
                if on_step is not None:
                    on_step(TrainingStep(step=k + 1, total_steps=cfg.steps, loss=loss_value,
                                         seconds=time.perf_counter() - start))
                if best.stop(k):
                    break
            with torch.no_grad():
                current = albedo()
                best.offer(k + 1, validation_error(torch.abs(op(current) - data) ** 2),
                           current)
                fitted = cast(torch.Tensor, best.albedo).cpu().numpy()
        finally:
            torch.set_num_threads(before)
        return TrainedVolume(fitted, history, loss_value, net.parameters_per_network,
                             steps=k + 1, best_validation=best.validation)


__all__ = ["NeuralVolumeTorch", "TorchPlaneOperator", "total_variation", "volume_albedo"]
