"""The multiresolution hash-grid encoding (Mueller et al. 2022) in torch.

A batch's encoding is a weighted sum of table rows: which rows and with what weights
depends only on the inputs (:class:`HashCorners`), so a trainer whose inputs are fixed
computes them once (:meth:`HashGridEncoding.corners`) and passes them instead of the
inputs at every step; only the tables are trained.
"""

from __future__ import annotations

import itertools
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from nlosfw.model.neural import HASH_PRIMES, HashGridLayout

#: The most bytes :meth:`HashGridEncoding.corners` may hold for a trainer's fixed inputs.
CORNERS_MAX_BYTES = 1 << 30


class HashCorners(NamedTuple):
    """The grid corners of N inputs: ``rows`` (N, L, 2^d) of the levels' tables stacked
    in order, their d-linear ``weights`` (N, L, 2^d), and the input columns the grid
    does not span (N, k)."""

    rows: torch.Tensor
    weights: torch.Tensor
    raw: torch.Tensor

    def select(self, index: torch.Tensor) -> HashCorners:
        """The corners of the inputs ``index`` (a 1-D index tensor)."""
        return HashCorners(*(t.index_select(0, index) for t in self))

    def part(self, start: int, stop: int) -> HashCorners:
        """The corners of inputs ``start:stop``."""
        return HashCorners(*(t[start:stop] for t in self))


class _WeightedRows(torch.autograd.Function):
    """See :func:`weighted_rows`.

    One ``index_select`` and a batched product forward, and one ``scatter_add`` per
    feature backward: on one CPU thread, 8192 inputs of 8 levels, 6 ms forward against
    14 ms for indexing and a weighted sum, 3 ms backward against 10 ms for indexing's own
    gradient (an accumulating ``index_put``).
    """

    generate_vmap_rule = True

    @staticmethod
    def forward(table: torch.Tensor, rows: torch.Tensor, weights: torch.Tensor
                ) -> torch.Tensor:
        n, levels, corners = rows.shape
        picked = table.index_select(0, rows.reshape(-1)).view(n * levels, corners, -1)
        summed = torch.bmm(weights.reshape(n * levels, 1, corners), picked)
        return summed.view(n, levels, -1)

    @staticmethod
    def setup_context(ctx: Any, inputs: tuple[Any, ...], output: Any) -> None:
        table, rows, weights = inputs
        ctx.save_for_backward(rows, weights)
        ctx.n_rows = int(table.shape[0])

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None, None]:
        rows, weights = ctx.saved_tensors
        flat = rows.reshape(-1)
        columns = [torch.zeros(ctx.n_rows, dtype=grad.dtype, device=grad.device).scatter_add(
            0, flat, (weights * grad[..., feature, None]).reshape(-1))
            for feature in range(grad.shape[-1])]
        return torch.stack(columns, dim=1), None, None


def weighted_rows(table: torch.Tensor, rows: torch.Tensor, weights: torch.Tensor
                  ) -> torch.Tensor:
    """sum_c w[n, l, c] T[r[n, l, c]] -> (N, L, F) for a table T (R, F), rows (N, L, C) and
    weights (N, L, C); differentiable in T (also under ``torch.vmap``)."""
    return _WeightedRows.apply(table, rows, weights)


class HashGridEncoding(nn.Module):
    """Multiresolution hash-grid features of the first ``layout.dims`` input columns (in
    (-1, 1), clamped), d-linearly interpolated per level; other columns are appended.
    Called with a :class:`HashCorners` instead of inputs, it skips finding the corners.
    Gradients flow to the tables, not to the inputs (the trainers need none there)."""

    corner_offsets: torch.Tensor

    def __init__(self, layout: HashGridLayout) -> None:
        super().__init__()
        self.layout = layout
        self.tables = nn.ParameterList(nn.Parameter(torch.zeros(rows, layout.features))
                                       for rows in layout.table_sizes)
        corners = torch.tensor(list(itertools.product((0, 1), repeat=layout.dims)))
        self.register_buffer("corner_offsets", corners, persistent=False)   # (2^d, d)

    def forward(self, x: torch.Tensor | HashCorners) -> torch.Tensor:
        found = x if isinstance(x, HashCorners) else self.corners(x)
        table = torch.cat(list(self.tables))
        features = weighted_rows(table, found.rows, found.weights)   # (N, L, F)
        return torch.cat([features.flatten(-2), found.raw], dim=-1)

    def corners(self, x: torch.Tensor) -> HashCorners:
        """The rows and weights of inputs ``x`` (N, D) (no gradient flows to ``x``)."""
        d, rows, weights = self.layout.dims, [], []
        offset = 0
        with torch.no_grad():
            u = ((x[:, :d] + 1) / 2).clamp(0, 1)
            for n, size in zip(self.layout.resolutions, self.layout.table_sizes, strict=True):
                cell = torch.clamp(torch.floor(u * n), max=n - 1)
                frac = (u * n - cell)[:, None, :]                          # (N, 1, d)
                vertex = cell.long()[:, None, :] + self.corner_offsets     # (N, 2^d, d)
                weights.append(torch.where(self.corner_offsets.bool(), frac, 1 - frac).prod(-1))
                rows.append(self._row(vertex, n, size) + offset)
                offset += size
        return HashCorners(torch.stack(rows, 1), torch.stack(weights, 1), x[:, d:])

    def corners_bytes(self, n_inputs: int) -> int:
        """Bytes :meth:`corners` returns for ``n_inputs`` inputs (raw columns aside)."""
        per_input = len(self.layout.resolutions) * 2 ** self.layout.dims
        return n_inputs * per_input * (np.dtype(np.int64).itemsize + 4)

    def _row(self, vertex: torch.Tensor, n: int, rows: int) -> torch.Tensor:
        """Table rows of grid vertices (..., d): row-major when every vertex has its own row,
        else the spatial hash (XOR of coordinate x prime) mod ``rows`` (a power of two)."""
        dense = (n + 1) ** self.layout.dims <= rows
        row = vertex[..., 0] * HASH_PRIMES[0]
        for axis in range(1, self.layout.dims):
            if dense:
                row = row + vertex[..., axis] * (n + 1) ** axis
            else:
                row = torch.bitwise_xor(row, vertex[..., axis] * HASH_PRIMES[axis])
        return row if dense else torch.bitwise_and(row, rows - 1)


__all__ = ["CORNERS_MAX_BYTES", "HashCorners", "HashGridEncoding", "weighted_rows"]
