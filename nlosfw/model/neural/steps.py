"""What each training step of the shared trainer is given: the learning rate of its
schedule, its batch of sample indices, and the network inputs of the samples."""

from __future__ import annotations

import math

import numpy as np

from nlosfw.model.neural.config import LRSchedule, NeuralFieldConfig


def learning_rate(config: NeuralFieldConfig, step: int) -> float:
    """Learning rate of (0-based) ``step``: linear warm-up, then the configured decay."""
    lr, total = config.lr, config.steps
    if step < config.warmup_steps:
        return lr * (0.01 + 0.99 * step / config.warmup_steps)
    span = max(1, total - config.warmup_steps - 1)
    t = min(1.0, (step - config.warmup_steps) / span)
    if config.lr_schedule == LRSchedule.cosine:
        return lr * (config.lr_final + (1 - config.lr_final) * 0.5 * (1 + math.cos(math.pi * t)))
    if config.lr_schedule == LRSchedule.exponential:
        return lr * config.lr_final ** t
    return lr


def field_inputs(xy: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
    """Network inputs (float32) from normalised coordinates (P, 2) and frequencies (F,).

    Single mode (``f`` None): (P, 2) = x, y. Multi mode: (F * P, 3) = x, y, f,
    frequency-major (row ``k * P + p`` is point p at frequency k).
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if f is None:
        return xy.astype(np.float32)
    f = np.asarray(f, dtype=np.float64).reshape(-1, 1)
    n_f, n_p = f.shape[0], xy.shape[0]
    return np.concatenate([np.tile(xy, (n_f, 1)), np.repeat(f, n_p, axis=0)],
                          axis=1).astype(np.float32)


class BatchStream:
    """Batches of sample indices: consecutive slices of fresh random permutations."""

    def __init__(self, n: int, batch: int, rng: np.random.Generator) -> None:
        self.n, self.batch, self.rng = n, batch, rng
        self.perm = rng.permutation(n)
        self.pos = 0

    def next(self) -> np.ndarray:
        """The next ``batch`` indices (a permutation ends: a fresh one goes on)."""
        parts, need = [], self.batch
        while need > 0:
            if self.pos >= self.n:
                self.perm, self.pos = self.rng.permutation(self.n), 0
            take = self.perm[self.pos:self.pos + need]
            parts.append(take)
            self.pos += take.size
            need -= take.size
        return np.concatenate(parts).astype(np.int64)
