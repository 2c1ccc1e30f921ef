"""neural_volume_jax's network pass in pieces (``volume_albedo`` with a chunk) against one
pass over every voxel, for every registered JAX network."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("optax")
eqx = pytest.importorskip("equinox")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from nlosfw_jax.backend import Fixed, JaxBackend  # noqa: E402
from nlosfw_jax.neural_volume import volume_albedo  # noqa: E402

from nlosfw.model.neural import FieldMode, FieldShape, NetworkBuild  # noqa: E402
from nlosfw.plugins import registered_network, registered_networks  # noqa: E402
from nlosfw.testing import fixtures  # noqa: E402


@pytest.mark.parametrize("name", registered_networks("jax"))
def test_the_albedo_in_pieces_equals_the_whole_and_so_does_its_gradient(name):
    """Every registered JAX network: the albedo computed 1000 voxels at a time (the last
    piece padded, each piece run again in the backward pass) equals one pass over all
    4 x 23 x 31 voxels (1e-6), and so do the gradients of a weighted sum by every
    parameter (1e-4 of the largest entry). The network sees pieces of 1000 points."""
    network = registered_network(name, "jax")
    engine = JaxBackend(NetworkBuild(network.network_factory, network.config_class(
        seed=3, hidden=[32, 32], device="cpu", steps=10), FieldShape(FieldMode.multi, (23, 31), 4)))
    sizes: list[int] = []

    def net_of(params):
        module = eqx.combine(params, engine.rest, is_leaf=lambda n: isinstance(n, Fixed))

        def net(x):
            sizes.append(x.shape[0])                 # recorded while JAX traces
            return module(x)
        return net

    coords, gain, weights = (jnp.asarray(a) for a in fixtures.volume_inputs((4, 23, 31)))
    results = []
    for chunk in (None, 1000):
        sizes.clear()

        def loss(params, chunk=chunk):
            albedo = volume_albedo(net_of(params), coords, gain, -3.0, chunk)
            return jnp.sum(albedo * weights), albedo

        grads, albedo = jax.grad(loss, has_aux=True)(engine.params)
        results.append((np.asarray(albedo), [np.asarray(g) for g in jax.tree.leaves(grads)],
                        set(sizes)))
    (whole, whole_grads, whole_sizes), (pieces, piece_grads, piece_sizes) = results
    assert whole_sizes == {2852}
    assert piece_sizes == {1000}
    assert pieces.shape == (4, 23, 31) and np.all(pieces > 0)
    np.testing.assert_allclose(pieces, whole, rtol=1e-6, atol=1e-6 * np.abs(whole).max())
    assert len(piece_grads) == len(whole_grads) > 0
    for a, b in zip(piece_grads, whole_grads, strict=True):
        assert np.abs(a - b).max() <= 1e-4 * np.abs(b).max() + 1e-12
