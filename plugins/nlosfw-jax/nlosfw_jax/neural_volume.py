"""``neural_volume_jax``: a registered JAX network's non-negative albedo on rsd_prior's
lattice, propagated to the wall by RSD in JAX
(:class:`nlosfw.model.hybrid.NeuralVolumeFieldModel`).

:class:`JaxPlaneOperator` is ``SceneOperator.forward`` in JAX (differentiable,
``jnp.fft``), from the numpy constants of :func:`nlosfw.model.hybrid.plane_stack`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from nlosfw.common import FitError
from nlosfw.model import TrainingStep
from nlosfw.model.hybrid import (
    BestStep,
    NeuralVolumeFieldModel,
    PlaneStack,
    TrainedVolume,
    VolumeProblem,
    aligned_empty,
    history_entry,
)
from nlosfw.model.neural import NetworkBuild, NeuralFieldModel
from nlosfw.plugins import registered_network
from nlosfw_jax.backend import Fixed, JaxBackend, resolve_device

#: Steps between entries of the fit history.
HISTORY_EVERY = 10
#: Adam as torch.optim.Adam with its defaults (the backend's).
_ADAM = optax.scale_by_adam(b1=0.9, b2=0.999, eps=1e-8)
#: Voxels per piece of the network's pass on the CPU (see :func:`volume_albedo`).
CPU_CHUNK = 4096


def volume_albedo(network: Callable[[jax.Array], jax.Array], coords: jax.Array,
                  gain: jax.Array, shift: float, chunk: int | None = None) -> jax.Array:
    """gain * softplus(network(coords) + shift), shaped as ``gain``.

    With ``chunk``, the network runs on ``chunk`` voxels at a time (``lax.map``, the last
    piece padded) and keeps none of its activations: each piece is run again in the
    backward pass (``jax.checkpoint``), as torch's neural volume does. The network must
    treat its points independently (every registered network does)."""
    def values(x: jax.Array) -> jax.Array:
        out = network(x)
        out = out.real if jnp.iscomplexobj(out) else out[..., 0]
        return jax.nn.softplus(out + shift)

    n = coords.shape[0]
    if chunk is None or n <= chunk:
        return gain * values(coords).reshape(gain.shape)
    pieces = -(-n // chunk)
    padded = jnp.concatenate([coords, jnp.zeros((pieces * chunk - n, coords.shape[1]),
                                                coords.dtype)])
    out = jax.lax.map(jax.checkpoint(values), padded.reshape(pieces, chunk, -1))
    return gain * out.reshape(-1)[:n].reshape(gain.shape)


def _is_fixed(node: Any) -> bool:
    return isinstance(node, Fixed)


class JaxPlaneOperator:
    """A a for an albedo a (Z, Y, X), real: the wall fields (F, ny, nx), complex, on
    ``device`` (None: JAX's default; see :class:`nlosfw.model.hybrid.PlaneStack`).

    A confocal scan on the CPU sums over planes as one product per lattice point (an
    ``einsum`` over the spectra reordered once as (Ly Lx, F, Z), as the torch operator
    does), faster on the CPU than the product summed over planes
    (``benchmarks/model/bench_volume_operator.py``; its numbers:
    ``studies/sparse_scans_measured/README.md``). A GPU and the single-spot case keep that
    sum.
    """

    def __init__(self, stack: PlaneStack, device: Any = None) -> None:
        platform = (device if device is not None else jax.devices()[0]).platform
        self.batched = stack.laser is None and platform == "cpu"
        z, n_f = stack.spectra.shape[:2]
        spectra = stack.spectra
        if self.batched:            # aligned, so that JAX holds it in place (one copy, not two)
            ly, lx = stack.spectra.shape[2:]
            spectra = aligned_empty((ly * lx, n_f, z), stack.spectra.dtype)
            spectra.reshape(ly, lx, n_f, z)[...] = stack.spectra.transpose(2, 3, 1, 0)
        self.spectra = jax.device_put(spectra, device)
        self.laser = None if stack.laser is None else jax.device_put(stack.laser, device)
        shape, inputs, outputs = stack.shape, stack.inputs, stack.outputs
        batched = self.batched

        def forward(albedo: jax.Array, spectra: jax.Array, laser: jax.Array | None
                    ) -> jax.Array:
            a = albedo.astype(spectra.dtype)[:, None]                  # (Z, 1, Y, X)
            source = a if laser is None else a * laser                 # (Z, 1 or F, Y, X)
            work = jnp.zeros(source.shape[:2] + shape, source.dtype)
            work = work.at[(..., inputs[0], inputs[1])].set(source)
            planes = jnp.fft.fft2(work)                                 # (Z, 1 or F, Ly, Lx)
            if batched:                                                 # (Ly Lx, F, Z) . (.., Z)
                columns = planes[:, 0].reshape(planes.shape[0], -1).T
                total = jnp.einsum("lfz,lz->lf", spectra, columns).T.reshape((-1,) + shape)
            else:
                total = jnp.sum(spectra * planes, axis=0)               # (F, Ly, Lx)
            return jnp.fft.ifft2(total)[(..., outputs[0], outputs[1])]

        self.forward = forward
        self._jitted = jax.jit(forward)

    def __call__(self, albedo: Any) -> jax.Array:
        return self._jitted(jnp.asarray(albedo), self.spectra, self.laser)


def total_variation(albedo: jax.Array) -> jax.Array:
    """:func:`nlosfw.model.hybrid.albedo_total_variation` of ``albedo`` (Z, Y, X), its
    sum held constant (no gradient flows through it)."""
    total = jnp.maximum(jax.lax.stop_gradient(jnp.sum(albedo)), jnp.finfo(albedo.dtype).tiny)
    return (jnp.sum(jnp.abs(jnp.diff(albedo, axis=2)))
            + jnp.sum(jnp.abs(jnp.diff(albedo, axis=1)))) / total


class NeuralVolumeJax(NeuralVolumeFieldModel):
    """A JAX (equinox) network's albedo propagated by RSD; on a GPU when JAX sees one."""

    backend = "jax"

    @classmethod
    def network_class(cls, name: str) -> type[NeuralFieldModel]:
        """The registered JAX network ``name``'s field-model class."""
        return registered_network(name, "jax")

    def stack_copies(self, confocal: bool) -> int:
        """Two on a confocal scan on the CPU (the operator's reordered spectra), else one
        (JAX uses :func:`plane_stack`'s aligned arrays in place on the CPU)."""
        return 2 if confocal and resolve_device(self.config.device).platform == "cpu" else 1

    def train(self, problem: VolumeProblem,
              on_step: Callable[[TrainingStep], None] | None = None) -> TrainedVolume:
        """Adam on the relative squared error of the propagated albedo (full batch), plus
        ``problem.tv_weight_at`` the step times its :func:`total_variation`."""
        cfg, who = self.config, self.model_name()
        start = time.perf_counter()
        net = JaxBackend(NetworkBuild(problem.network.network_factory,
                                        problem.network_config, problem.network_shape,
                                        who=who))
        device = net.device
        op = JaxPlaneOperator(problem.stack, device)
        coords, gain, data, train = (
            jax.device_put(a, device)
            for a in (problem.coords, problem.gain, problem.data, problem.train))
        power = np.abs(problem.data) ** 2
        train_power = float(np.sum(power * problem.train))
        has_val = problem.validation is not None
        val = jax.device_put(problem.validation if has_val else problem.train, device)
        val_power = float(np.sum(power * problem.validation)) if has_val else 1.0
        chunk = CPU_CHUNK if device.platform == "cpu" else None

        def albedo(params: Any, rest: Any) -> jax.Array:
            return volume_albedo(eqx.combine(params, rest, is_leaf=_is_fixed), coords, gain,
                                 problem.shift, chunk)

        # the operator's constants are arguments: closed over, XLA folds them into the
        # programs (70 planes x 135 frequencies on 2 cores: 1 step took 101 s, now 13 s)
        constants = (op.spectra, op.laser)

        def loss_of(params: Any, rest: Any, constants: tuple[jax.Array, jax.Array | None],
                    tv: jax.Array) -> tuple[jax.Array, tuple[jax.Array, jax.Array]]:
            current = albedo(params, rest)
            squared = jnp.abs(op.forward(current, *constants) - data) ** 2
            error = jnp.sum(squared * val) / val_power
            loss = jnp.sum(squared * train) / train_power
            if problem.tv_weight > 0:
                loss = loss + tv * total_variation(current)
            return loss, (error, current)

        @jax.jit
        def step(params: Any, rest: Any, opt_state: Any, lr: jax.Array,
                 constants: tuple[jax.Array, jax.Array | None], tv: jax.Array
                 ) -> tuple[Any, Any, jax.Array, jax.Array, jax.Array]:
            (loss, (error, current)), grads = jax.value_and_grad(loss_of, has_aux=True)(
                params, rest, constants, tv)
            updates, opt_state = _ADAM.update(grads, opt_state, params)
            params = jax.tree.map(lambda p, u: p - lr * u, params, updates)
            return params, opt_state, loss, error, current

        params, rest = net.params, net.rest
        opt_state = _ADAM.init(params)
        history: list[dict[str, float]] = []
        best = BestStep(cfg.patience, cfg.average_steps)
        loss_value = math.nan
        k = 0
        for k in range(cfg.steps):
            params, opt_state, loss, error, current = step(
                params, rest, opt_state, jnp.asarray(self.learning_rate(k), jnp.float32),
                constants, jnp.asarray(problem.tv_weight_at(k), jnp.float32))
            loss_value = float(loss)
            if not math.isfinite(loss_value):
                raise FitError(f"{who}: training diverged at step {k + 1} (loss "
                               f"{loss_value}); lower model.lr")
            val_error = float(error) if has_val else None
            best.offer(k, val_error, current)
            if k == 0 or (k + 1) % HISTORY_EVERY == 0 or k + 1 == cfg.steps:
                history.append(history_entry(k + 1, loss_value, val_error))
            if on_step is not None:
                on_step(TrainingStep(step=k + 1, total_steps=cfg.steps, loss=loss_value,
                                     seconds=time.perf_counter() - start))
            if best.stop(k):
                break
        _, (error, current) = jax.jit(loss_of)(params, rest, constants,
                                               jnp.asarray(0.0, jnp.float32))
        best.offer(k + 1, float(error) if has_val else None, current)
        fitted = np.asarray(jax.device_get(best.albedo))
        return TrainedVolume(fitted, history, loss_value, net.parameters_per_network,
                             steps=k + 1, best_validation=best.validation)


__all__ = ["JaxPlaneOperator", "NeuralVolumeJax", "total_variation", "volume_albedo"]
