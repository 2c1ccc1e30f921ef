"""The memory a run will need, estimated from its configuration before anything is allocated.

A wall of 10⁵ × 10⁵ sensors or a billion time bins would otherwise end, after a long wait,
in a ``MemoryError`` traceback. :func:`check_memory` refuses such a run with one line giving
the estimate, what dominates it and the memory available; ``limits.allow_large=true`` runs
it anyway. The estimate adds up the arrays a run holds at once (order of magnitude, on the
generous side), with S sensors, L laser points, B time bins, F frequencies, D depth planes
and M field models:

=================  ===========================================================
the transient      16·B·S·L bytes (float64 histogram while rendering, float32
                   capture, its HDF5 image), and 4·B·S·L more with noise
the transform      8·B·S·L (the spectrum) + 16·F·S·L per field (2 with noise)
the fields         16·F·S·(2 + M) (true, raw, each model's prediction)
the voxels         8·D·S·(3 + (2 + M)·(1 + single-frequency images)); D, when it is
                   automatic, at most the time window over half a wall spacing
training logs      400 bytes per evaluation (steps / eval_every) of neural models
neural models      their runtime (PyTorch, JAX), training memory and network parameters
                   (with their gradients and Adam's moments), from figures measured per
                   backend and the networks' own layer shapes
                   (:mod:`nlosfw.pipeline.model_budget`); given ``requires``
the program        with ``program=True``: this process's resident memory now (Python,
                   numpy, h5py, Hydra and the plugins loaded), which the run keeps
=================  ===========================================================

The check against the memory available leaves the program out (the memory available is
what is left beside it); the log's summary and ``benchmarks/bench_memory.py``, which
compares the estimate with a run's measured peak resident memory, count it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from nlosfw.common.errors import ConfigError
from nlosfw.common.files import format_bytes
from nlosfw.common.memory import available_memory
from nlosfw.pipeline.model_budget import (
    ModelCatalogue,
    ModelRequires,
    backend_of,
    parameter_bytes,
    runtime_bytes,
    training_bytes,
)
from nlosfw.pipeline.settings import NO_MODEL

if TYPE_CHECKING:
    from nlosfw.model.neural import FieldShape

#: Sizes a capture file from its header: (time bins, sensor points, laser points), or None.
FileShape = Callable[[Path], tuple[int, int, int] | None]

#: Bytes one entry of a neural model's training history takes (a small dict of floats).
_HISTORY_ENTRY = 400


@dataclass(frozen=True)
class MemoryPart:
    """One part of the estimate: what it holds, the options that size it, its bytes."""

    what: str
    why: str
    nbytes: float


def _get(config: Mapping[str, object] | None, dotted: str, default: object = None) -> Any:
    node: object = config
    for key in dotted.split("."):
        if not isinstance(node, Mapping):
            return default
        node = node.get(key)
    return default if node is None else node


def _capture_shape(config: Mapping[str, object], file_shape: FileShape | None
                   ) -> tuple[int, int, int, str] | None:
    """(B, S, L, why) from ``capture.path`` (its header, through ``file_shape``) or the
    scene; None when the file's size is unknown."""
    path = _get(config, "capture.path")
    if path is not None:
        shape = None if file_shape is None else file_shape(Path(str(path)).expanduser())
        if shape is None:
            return None
        bins, sensors, lasers = shape
        return bins, sensors, lasers, (f"capture.path's transient of {bins} time bins × "
                                       f"{sensors * lasers} samples")
    res = _get(config, "scene.wall.resolution", (64, 64))
    bins = int(_get(config, "scene.time.bins", 2048))
    sensors = math.prod(int(r) for r in res)
    return bins, sensors, 1, (f"scene.wall.resolution {list(res)} × scene.time.bins {bins}")


def _n_frequencies(config: Mapping[str, object], bins: int) -> int:
    given = _get(config, "transform.frequencies")
    if given:
        return len(given)
    count = _get(config, "transform.n_frequencies")
    return int(count) if count is not None else max(1, bins // 2)  # at most the DFT's bins


def _n_depths(config: Mapping[str, object], bins: int) -> int:
    """Depth planes: as configured, else at most what the automatic rule can choose (planes
    at least half a wall spacing apart over half the time window, at most its maximum)."""
    from nlosfw.image.depths import MAX_AUTOMATIC_PLANES

    given = len(_get(config, "reconstruction.depths", ()) or ())
    count = _get(config, "reconstruction.n_depths")
    if given or count is not None:
        return given or int(count)
    size, res = _get(config, "scene.wall.size"), _get(config, "scene.wall.resolution")
    width = _get(config, "scene.time.bin_width")
    if _get(config, "capture.path") is not None or not (size and res and width):
        return MAX_AUTOMATIC_PLANES
    spacing = min(float(s) / max(int(r), 1) for s, r in zip(size, res, strict=False))
    ratio = bins * float(width) / spacing if spacing > 0 else math.inf
    if not math.isfinite(ratio):  # a non-finite size is refused by the scene's own checks
        return MAX_AUTOMATIC_PLANES
    return max(2, min(MAX_AUTOMATIC_PLANES, math.ceil(ratio) + 1))


def _history(options: Mapping[str, object] | None) -> float:
    steps, every = _get(options, "steps"), _get(options, "eval_every", 1)
    if steps is None:
        return 0.0
    return float(steps) / max(int(every), 1) * _HISTORY_ENTRY


def process_memory() -> int:
    """This process's resident memory now (bytes; 0 when unknown)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return 0
    return pages * os.sysconf("SC_PAGE_SIZE")


def estimate_memory(config: Mapping[str, object], file_shape: FileShape | None = None,
                    program: bool = False, requires: ModelRequires | None = None
                    ) -> list[MemoryPart]:
    """The parts of the memory a run of ``config`` (composed, validated) needs, in bytes;
    ``file_shape``: how to size a ``capture.path`` from its header (none: unknown, no
    estimate for such a run); ``program``: count this process's own resident memory too
    (the interpreter and its libraries, as the run will hold them); ``requires``: the
    modules each field model needs (:func:`~nlosfw.pipeline.model_budget.plugin_requires`;
    none: neural models' own memory is left out)."""
    shape = _capture_shape(config, file_shape)
    if shape is None:
        return []
    parts = _array_parts(config, shape)
    if requires is not None:
        parts.extend(_model_parts(config, shape, requires))
    if program:
        parts.append(MemoryPart("the program", "Python and the libraries loaded (resident "
                                "memory now)", float(process_memory())))
    return parts


def _array_parts(config: Any, shape: tuple[int, int, int, str]) -> list[MemoryPart]:
    """The arrays of :func:`estimate_memory`."""
    bins, sensors, lasers, why = shape
    samples = float(bins) * sensors * lasers
    noisy = _get(config, "scene.noise.model", "none") != "none" and not _get(config,
                                                                           "capture.path")
    freqs = _n_frequencies(config, bins)
    compare = _get(config, "compare", {}) or {}
    name = str(_get(config, "model.name"))
    # true, raw, interp, the model and each compare label; model=none: the capture's alone
    fields = 1 if name == NO_MODEL else 3 + (name != "interp") + len(compare)
    depths = _n_depths(config, bins)
    singles = (0 if name == NO_MODEL
               else int(_get(config, "reconstruction.single_frequency_images", 2)))
    history = _history(_get(config, "model")) + sum(_history(o) for o in compare.values())
    per_field = 16.0 * freqs * sensors * lasers
    # count splitting: halves A and B, B's field, the ceiling
    thinned = bool(_get(config, "split.count_splitting", False))
    imaged = fields + int(thinned)
    return [
        MemoryPart("the transient H", why,
                   samples * (20 if noisy else 16) + (24 * samples if thinned else 0)),
        MemoryPart("the phasor transform", f"{why}, {freqs} frequencies",
                   8 * samples + per_field * ((2 if noisy else 1) + (2 if thinned else 0))),
        MemoryPart("the fields imaged", f"{freqs} frequencies × {sensors * lasers} samples × "
                   f"{imaged} fields", 16.0 * freqs * sensors * imaged),
        MemoryPart("the voxels and images", f"{depths} depth planes × {sensors} voxels each",
                   8.0 * depths * sensors * (3 + fields * (1 + singles))),
        MemoryPart("the training history", "model.steps / model.eval_every", history),
    ]


def _field_shape(config: Mapping[str, object], sensors: int, freqs: int) -> FieldShape:
    """The shape of the field a network trains on: the scene's wall grid, or for a file
    the square grid of as many sensor points."""
    from nlosfw.model.neural import FieldMode, FieldShape

    res = _get(config, "scene.wall.resolution")
    if _get(config, "capture.path") is None and res is not None and len(res) == 2:
        grid = (int(res[1]), int(res[0]))
    else:
        side = max(1, math.isqrt(max(sensors - 1, 0)) + 1)
        grid = (side, side)
    return FieldShape(FieldMode.multi, grid, freqs)


def _model_parts(config: Mapping[str, object], shape: tuple[int, int, int, str],
                 requires: ModelRequires) -> list[MemoryPart]:
    """The neural models' runtime, training and parameter memory (none for other models)."""
    bins, sensors, lasers, _ = shape
    freqs = _n_frequencies(config, bins)
    samples = float(freqs) * sensors * lasers
    field = _field_shape(config, sensors, freqs)
    model = _get(config, "model") or {}
    compare = _get(config, "compare", {}) or {}
    backends, data, activations, weights, counted = [], 0.0, 0.0, 0.0, []
    for where, options in (("model", model), *((f"compare.{k}", v) for k, v in compare.items())):
        name = str(_get(options, "name"))
        backend = None if name == NO_MODEL else backend_of(requires(name))
        if backend is None:
            continue
        backends.append(backend)
        held, batch = training_bytes(options, backend, samples)
        data, activations = data + held, activations + batch
        count = (requires.parameters(name, options, field)
                 if isinstance(requires, ModelCatalogue) else None)
        if count:
            weights += parameter_bytes(count, backend)
            counted.append(f"{where} ({name}): {count:,} parameters")
    if not backends:
        return []
    names = " and ".join(sorted(set(backends)))
    parts = [MemoryPart("the model's runtime", f"{names} and its first training",
                        runtime_bytes(backends)),
             MemoryPart("the model's training", f"{samples:.0f} samples, model.batch_size × "
                        "model.hidden", data + activations)]
    if counted:
        parts.append(MemoryPart("the networks' parameters",
                                f"{'; '.join(counted)}, each with its gradient and Adam's two "
                                "moments", weights))
    return parts


def check_memory(config: Mapping[str, object], available: int | None = None,
                 file_shape: FileShape | None = None,
                 requires: ModelRequires | None = None) -> None:
    """Refuse (one-line :class:`ConfigError`) a run whose estimated memory exceeds what is
    available, unless ``limits.allow_large`` is true. ``available``: bytes (default: this
    machine's); ``file_shape``, ``requires``: see :func:`estimate_memory`."""
    if bool(_get(config, "limits.allow_large", False)):
        return
    parts = estimate_memory(config, file_shape, requires=requires)
    total = sum(p.nbytes for p in parts)
    room = available_memory() if available is None else available
    if room is None or total <= room:
        return
    top = max(parts, key=lambda p: p.nbytes)
    raise ConfigError("", f"this run needs about {format_bytes(total)} of "
                      f"memory, most of it for {top.what} ({top.why}: "
                      f"{format_bytes(top.nbytes)}), but {format_bytes(room)} are available; "
                      "make it smaller, or set limits.allow_large=true to run anyway")


def memory_summary(config: Mapping[str, object], file_shape: FileShape | None = None,
                   requires: ModelRequires | None = None) -> str:
    """The estimate as one line (for the log), the program itself included."""
    parts = estimate_memory(config, file_shape, program=True, requires=requires)
    total = sum(p.nbytes for p in parts)
    return f"estimated memory {format_bytes(total)}: " + ", ".join(
        f"{p.what} {format_bytes(p.nbytes)}" for p in parts if p.nbytes)
