"""The JAX backend: runs any equinox module under the shared trainer, with optax's Adam.

Why equinox: its modules are plain JAX pytrees (dataclasses of arrays), so one
jitted step (``jax.value_and_grad`` + ``optax``) and ``vmap`` over a stacked batch of
networks (single mode) serve every network without framework state; it is a small,
pure-Python, actively maintained library (three small dependencies) that installs
from PyPI next to ``jax`` and ``optax`` on CPU. flax.nnx would pull in orbax,
tensorstore and a dozen more packages for the same.

The module (``factory(config, shape, key)``) maps normalised inputs (N, in_dim)
float32 to (N, 2) = (Re, Im) or to a complex (N,). Its floating-point arrays are
trained, except those wrapped in :class:`Fixed` (e.g. a random Fourier matrix);
array names are their dotted paths (``layers.0.weight``; a Fixed array: its wrapper's
path, ``features.B``, as torch names a buffer). Step functions are
jitted once per network structure and reused across model instances. JAX picks
its own CPU thread count (``threads`` is ignored).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from nlosfw.common import ConfigError, FitError, one_line
from nlosfw.model.neural import Backend, NetworkBuild, SmoothnessBatch
from nlosfw_jax.devices import check_device

#: Adam exactly as torch.optim.Adam with its defaults (eps outside the square root).
_ADAM = optax.scale_by_adam(b1=0.9, b2=0.999, eps=1e-8)


class Fixed(eqx.Module):
    """An array a network keeps fixed: saved with it, never trained (torch's buffer)."""

    value: jax.Array


def resolve_device(name: str) -> Any:
    """``auto`` -> JAX's default device (a GPU when jaxlib has one), else a named platform."""
    if name == "auto":
        return jax.devices()[0]
    platform, _, index = name.partition(":")
    platform = {"cuda": "gpu"}.get(platform, platform)
    try:
        return jax.devices(platform)[int(index or 0)]
    except (RuntimeError, ValueError, IndexError) as err:
        raise ConfigError("model.device", f"JAX cannot use device {name!r} ({one_line(err)}); "
                          "valid: auto, cpu, gpu, gpu:N") from None


# ------------------------------------------------------------------ pytree helpers
def _is_fixed(node: Any) -> bool:
    return isinstance(node, Fixed)


def _name(path: tuple[Any, ...]) -> str:
    parts = []
    for key in path:
        for attr in ("name", "idx", "key"):
            if hasattr(key, attr):
                parts.append(str(getattr(key, attr)))
                break
    return ".".join(parts)


def _arrays(tree: Any) -> dict[str, Any]:
    """The arrays of ``tree`` by dotted path; a :class:`Fixed` array by the path of its
    wrapper (``features.B``, as torch names a buffer), so files load across backends."""
    found = {}
    for path, leaf in jax.tree_util.tree_leaves_with_path(tree, is_leaf=_is_fixed):
        value = leaf.value if _is_fixed(leaf) else leaf
        if eqx.is_array(value):
            found[_name(path)] = value
    return found


def _placed(leaf: Any, value: Any) -> Any:
    """``leaf`` (an array, or a Fixed one) replaced by the device array ``value``."""
    return Fixed(value) if _is_fixed(leaf) else value


def _trainable_spec(tree: Any) -> Any:
    return jax.tree.map(lambda x: not _is_fixed(x) and eqx.is_inexact_array(x), tree,
                        is_leaf=_is_fixed)


def _pairs(out: jax.Array) -> jax.Array:
    return jnp.stack([out.real, out.imag], axis=-1) if jnp.iscomplexobj(out) else out


def _apply(params: Any, rest: Any, x: jax.Array, single: bool) -> jax.Array:
    def one(p: Any, r: Any) -> jax.Array:
        return _pairs(eqx.combine(p, r, is_leaf=_is_fixed)(x))

    return eqx.filter_vmap(one)(params, rest) if single else one(params, rest)


def _loss(params: Any, rest: Any, batch: tuple[Any, Any, Any], single: bool
          ) -> tuple[jax.Array, jax.Array]:
    """(Data loss plus the smoothness penalty, data loss); ``batch`` = (inputs, targets,
    None or the penalty's (inputs, matrix D, weight))."""
    x, y, smooth = batch
    loss = jnp.mean(jnp.square(_apply(params, rest, x, single) - y))
    if smooth is None:
        return loss, loss
    sx, matrix, weight = smooth
    out = _apply(params, rest, sx, single).reshape(matrix.shape[1], -1, 2)
    return loss + weight * jnp.mean(jnp.square(jnp.tensordot(matrix, out, 1))), loss


@eqx.filter_jit
def _step(params: Any, rest: Any, opt_state: Any, batch: tuple[Any, Any, Any, Any],
          lr: jax.Array, single: bool) -> tuple[Any, Any, jax.Array]:
    """One Adam step on ``batch`` = (inputs, targets, row indices or None for all rows,
    None or the smoothness penalty's (inputs, matrix, weight))."""
    x, y, idx, smooth = batch
    if idx is not None:
        x, y = jnp.take(x, idx, axis=0), jnp.take(y, idx, axis=-2)
    (_, loss), grads = jax.value_and_grad(_loss, has_aux=True)(params, rest, (x, y, smooth),
                                                                single)
    updates, opt_state = _ADAM.update(grads, opt_state, params)
    params = jax.tree.map(lambda p, u: p - lr * u, params, updates)
    return params, opt_state, loss


@eqx.filter_jit
def _sum_squared_error(params: Any, rest: Any, x: jax.Array, y: jax.Array,
                       single: bool) -> jax.Array:
    return jnp.sum(jnp.square(_apply(params, rest, x, single) - y))


@eqx.filter_jit
def _forward(params: Any, rest: Any, x: jax.Array, single: bool) -> jax.Array:
    return _apply(params, rest, x, single)


class JaxBackend(Backend):
    """An equinox module's arrays and optax Adam's state on one device (float32)."""

    @classmethod
    def check_device(cls, name: str) -> None:
        check_device(name)

    def __init__(self, build: NetworkBuild, state: Mapping[str, np.ndarray] | None = None
                 ) -> None:
        self.device = resolve_device(build.config.device)
        super().__init__(build, state)

    # ------------------------------------------------------------------ building
    def make_network(self, index: int) -> Any:
        key = jax.random.fold_in(jax.random.key(self.build.config.seed), index)
        network = self.build.factory(self.build.config, self.build.shape, key)
        if not isinstance(network, eqx.Module):
            raise FitError(f"{self.build.who}: the network factory returned "
                           f"{type(network).__name__}, not an equinox.Module")
        return network

    def network_state(self, network: Any) -> dict[str, np.ndarray]:
        return {k: np.array(v) for k, v in _arrays(network).items()}

    def trainable(self, network: Any) -> set[str]:
        return set(_arrays(eqx.filter(network, _trainable_spec(network), is_leaf=_is_fixed)))

    def place(self, network: Any, state: Mapping[str, np.ndarray]) -> None:
        leaves, treedef = jax.tree_util.tree_flatten_with_path(network, is_leaf=_is_fixed)
        placed = [_placed(leaf, self.to_device(state[_name(path)])) if _name(path) in state
                  else leaf for path, leaf in leaves]
        model = jax.tree_util.tree_unflatten(treedef, placed)
        self.params, self.rest = eqx.partition(model, _trainable_spec(model), is_leaf=_is_fixed)
        self.opt_state = _ADAM.init(self.params)

    # ------------------------------------------------------------------ training
    def to_device(self, a: np.ndarray) -> Any:
        a = np.asarray(a)
        if np.issubdtype(a.dtype, np.floating):
            a = a.astype(np.float32)
        return jax.device_put(np.ascontiguousarray(a), self.device)

    def step(self, idx: np.ndarray | None, lr: float, smooth: SmoothnessBatch | None = None
             ) -> Any:
        index = None if idx is None else jax.device_put(idx.astype(np.int32), self.device)
        penalty = None if smooth is None else (
            self.to_device(smooth.x), self.to_device(smooth.matrix),
            jnp.asarray(smooth.weight, dtype=jnp.float32))
        self.params, self.opt_state, loss = _step(
            self.params, self.rest, self.opt_state, (*self.training_data(), index, penalty),
            jnp.asarray(lr, dtype=jnp.float32), bool(self.n_networks))
        return loss

    def mean_loss(self, handles: list[Any]) -> float:
        return float(np.mean(np.asarray(jax.device_get(handles), dtype=np.float64)))

    def squared_error(self, start: int, stop: int) -> tuple[float, int]:
        val_x, val_y = self.validation_data()
        y = val_y[..., start:stop, :]
        err = _sum_squared_error(self.params, self.rest, val_x[start:stop], y,
                                 bool(self.n_networks))
        return float(err), int(np.prod(y.shape))

    def snapshot(self) -> Any:
        return self.params                # JAX arrays are immutable

    def restore(self, snapshot: Any) -> None:
        self.params = snapshot

    def state(self) -> dict[str, np.ndarray]:
        model = eqx.combine(self.params, self.rest, is_leaf=_is_fixed)
        return {k: np.array(jax.device_get(v)) for k, v in _arrays(model).items()}

    # ------------------------------------------------------------------ prediction
    def evaluate(self, x: np.ndarray, networks: np.ndarray | None) -> np.ndarray:
        params, rest = self.params, self.rest
        if networks is not None:
            sel = jnp.asarray(networks.astype(np.int32))
            params, rest = (jax.tree.map(
                lambda a: jnp.take(a, sel, axis=0) if eqx.is_array(a) else a, t)
                for t in (params, rest))
        out = _forward(params, rest, self.to_device(x), bool(self.n_networks))
        return np.asarray(out, dtype=np.float32)
