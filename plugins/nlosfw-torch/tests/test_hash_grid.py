"""The torch hash grid's weighted table lookup and its corners computed once per fit,
against indexing, autograd and a fit that finds the corners at every step."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import nlosfw_torch.networks as networks  # noqa: E402
from nlosfw_torch.hash_grid import HashGridEncoding, weighted_rows  # noqa: E402

from nlosfw.model.neural import FieldMode, FieldShape, HashGridFieldConfig, hash_grid_layout  # noqa: E402
from nlosfw.plugins import load_plugins  # noqa: E402
from nlosfw.testing import fixtures  # noqa: E402


def _corners(levels: int = 5, n: int = 40):
    layout = hash_grid_layout(HashGridFieldConfig(levels=levels, log2_table_size=6),
                              FieldShape(FieldMode.multi, (16, 16), 20))
    encoding = HashGridEncoding(layout)
    x = torch.rand(n, 3, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    return layout, encoding.corners(x * 2.4 - 1.2)


def _lookup(table, corners):
    """The lookup by indexing and a weighted sum (autograd's own gradient)."""
    return (corners.weights.double()[..., None] * table[corners.rows]).sum(-2)


def test_weighted_rows_match_indexing_and_autograd():
    """Its value equals indexing's; its gradient passes gradcheck (float64) and equals
    autograd's gradient of indexing, rows repeated across inputs and levels included."""
    layout, corners = _corners()
    assert bool(layout.hashed[-1])                                 # some levels hash
    rows = int(sum(layout.table_sizes))
    table = torch.rand(rows, 2, dtype=torch.float64, requires_grad=True)
    weights = corners.weights.double()
    got = weighted_rows(table, corners.rows, weights)
    want = _lookup(table, corners)
    assert got.shape == (40, 5, 2)
    torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-12)
    grad = torch.rand_like(got)
    (g_got,) = torch.autograd.grad(got, table, grad)
    (g_want,) = torch.autograd.grad(want, table, grad)
    torch.testing.assert_close(g_got, g_want, rtol=1e-12, atol=1e-12)
    assert torch.autograd.gradcheck(lambda t: weighted_rows(t, corners.rows, weights),
                                    (table,))


def test_weighted_rows_under_vmap_match_one_table_at_a_time():
    """Three stacked tables (single mode's networks) through vmap: values and gradients
    equal those of each table alone."""
    layout, corners = _corners()
    weights = corners.weights.double()
    tables = torch.rand(3, int(sum(layout.table_sizes)), 2, dtype=torch.float64,
                        requires_grad=True)
    got = torch.vmap(lambda t: weighted_rows(t, corners.rows, weights))(tables)
    want = torch.stack([_lookup(t, corners) for t in tables])
    torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-12)
    grad = torch.rand_like(got)
    torch.testing.assert_close(torch.autograd.grad(got, tables, grad)[0],
                               torch.autograd.grad(want, tables, grad)[0],
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mode", ["multi", "single"])
def test_a_fit_with_corners_found_once_equals_one_finding_them_every_step(mode, monkeypatch):
    """Batches of 64 of the training inputs, validation every 10 steps: the losses, the
    validation errors and the prediction equal (rtol 1e-4) those of the same fit with
    precomputing disabled (its byte cap set to 0), which finds corners for every batch."""
    field = fixtures.point_phasor_field((0.1, -0.05, 0.7), n=12,
                                        frequencies=np.linspace(2.0, 3.0, 6))
    options = {"steps": 40, "eval_every": 10, "batch_size": 64, "device": "cpu",
               "mode": mode, "levels": 4, "log2_table_size": 8}
    registry = load_plugins().registry
    found = HashGridEncoding.corners
    calls: list[int] = []

    def counted(self, x):
        calls.append(int(x.shape[0]))
        return found(self, x)

    monkeypatch.setattr(HashGridEncoding, "corners", counted)
    fits = []
    for cap in (networks.CORNERS_MAX_BYTES, 0):
        monkeypatch.setattr(networks, "CORNERS_MAX_BYTES", cap)
        model = registry.create("model", "hashgrid_torch", options)
        calls.clear()
        report = model.fit(field)
        fits.append((report, model.predict(field.wall_xyz[..., :2], field.frequencies),
                     list(calls)))
    (fast, fast_pred, fast_calls), (slow, slow_pred, slow_calls) = fits
    # found once for the training and once for the validation inputs, never per batch
    assert 64 not in fast_calls and len(fast_calls) == 4, fast_calls
    assert slow_calls.count(64) == 40, slow_calls
    assert fast.steps == slow.steps == 40 and len(fast.history) == 4
    for a, b in zip(fast.history, slow.history, strict=True):
        assert set(a) == set(b) and "val_loss" in a
        for key in set(a) - {"seconds"}:
            assert a[key] == pytest.approx(b[key], rel=1e-4), key
    np.testing.assert_allclose(fast_pred, slow_pred, rtol=1e-4, atol=1e-6 * np.abs(
        slow_pred).max())
