"""The memory a run will need, estimated by its plan before anything is allocated.

A wall of 10⁵ × 10⁵ sensors or a billion time bins would otherwise end, after a long wait,
in a ``MemoryError`` traceback. :func:`check_memory` refuses such a run with one line giving
the estimate, what dominates it and the memory available; ``limits.allow_large=true`` runs
it anyway. The estimate adds up the arrays a run holds at once (order of magnitude, on the
generous side), from the sizes the plan knows (:class:`~nlosfw.common.memory.PlanShape`:
S sensors, L laser points, B time bins, F frequencies) and the run's counts
(:class:`RunCounts`: D depth planes, M field models, whether the capture is read):

=================  ===========================================================
the transient      16·B·S·L bytes (float64 histogram while rendering, float32
                   capture, its HDF5 image), and 4·B·S·L more with noise; a capture
                   read from a file 12·B·S·L (the file's float64 image, the float32
                   capture)
the transform      8·B·S·L (the spectrum) + 16·F·S·L per field (2 with noise)
the fields         16·F·S·(2 + M) (true, raw, each model's prediction)
the voxels         8·D·S·(3 + (2 + M)·(1 + single-frequency images)); D, when it is
                   automatic, at most the time window over half a wall spacing
each field model   what it estimates itself (:meth:`~nlosfw.model.FieldModel.estimate_memory`:
                   a neural model's runtime, training and parameters,
                   :mod:`nlosfw.model.neural.memory`; the neural volume's operator,
                   :mod:`nlosfw.model.hybrid.volume_memory`; nothing by default), a
                   runtime that several models load counted once
the program        (the log's summary and ``benchmarks/pipeline/bench_memory.py``): this process's
                   resident memory now (Python, numpy, h5py, Hydra, the plugins loaded),
                   which the run keeps
=================  ===========================================================

The check against the memory available leaves the program out (the memory available is
what is left beside it); the log's summary and ``benchmarks/pipeline/bench_memory.py``, which
compares the estimate with a run's measured peak resident memory, count it. The engine
knows no plugin's options: the models' parts are theirs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from nlosfw.common.errors import ConfigError
from nlosfw.common.files import format_bytes
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape, available_memory


@dataclass(frozen=True)
class RunCounts:
    """What the engine's own arrays are counted from beside the sizes: the field models
    fitted (0: ``model=none``), whether the simulated capture is ``noisy`` (its noise-free
    twin is kept) or split in two (``thinned``), the most depth planes, the single-frequency
    images per field, where the sizes come from (``why``, one line) and whether the
    capture is ``read`` from a file (no histogram rendered)."""

    models: int
    noisy: bool
    thinned: bool
    depth_planes: int
    single_frequency_images: int
    why: str
    read: bool = False


def process_memory() -> int:
    """This process's resident memory now (bytes; 0 when unknown)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return 0
    return pages * os.sysconf("SC_PAGE_SIZE")


def array_parts(shape: PlanShape, counts: RunCounts) -> MemoryEstimate:
    """The arrays the engine itself holds (the table's first four rows)."""
    samples = float(shape.bins) * shape.sensors * shape.lasers
    freqs, sensors = shape.frequencies, shape.sensors
    # true and raw, each model's prediction; model=none: the capture's alone
    fields = 1 if counts.models == 0 else 2 + counts.models
    singles = 0 if counts.models == 0 else counts.single_frequency_images
    per_field = 16.0 * freqs * sensors * shape.lasers
    thinned = counts.thinned                 # halves A and B, B's field, the ceiling
    imaged = fields + int(thinned)
    held = 12 if counts.read else (20 if counts.noisy else 16)   # bytes per sample
    return MemoryEstimate((
        MemoryPart("the transient H", counts.why,
                   samples * held + (24 * samples if thinned else 0)),
        MemoryPart("the phasor transform", f"{counts.why}, {freqs} frequencies",
                   8 * samples + per_field * ((2 if counts.noisy else 1) + (2 if thinned else 0))),
        MemoryPart("the fields imaged", f"{freqs} frequencies × {sensors * shape.lasers} "
                   f"samples × {imaged} fields", 16.0 * freqs * sensors * imaged),
        MemoryPart("the voxels and images", f"{counts.depth_planes} depth planes × {sensors} "
                   "voxels each",
                   8.0 * counts.depth_planes * sensors * (3 + fields * (1 + singles))),
    ))


def program_part() -> MemoryPart:
    """This process's resident memory now, which the run keeps."""
    return MemoryPart("the program", "Python and the libraries loaded (resident memory now)",
                      float(process_memory()))


def check_memory(estimate: MemoryEstimate, allow_large: bool = False,
                 available: int | None = None) -> None:
    """Refuse (one-line :class:`ConfigError`) a run whose estimated memory exceeds what is
    available, unless ``allow_large`` (``limits.allow_large``). ``available``: bytes
    (default: this machine's)."""
    if allow_large:
        return
    parts = estimate.merged()
    total = estimate.total
    room = available_memory() if available is None else available
    if room is None or total <= room or not parts:
        return
    top = max(parts, key=lambda p: p.nbytes)
    raise ConfigError("", f"this run needs about {format_bytes(total)} of "
                      f"memory, most of it for {top.what} ({top.why}: "
                      f"{format_bytes(top.nbytes)}), but {format_bytes(room)} are available; "
                      "make it smaller, or set limits.allow_large=true to run anyway")


def memory_summary(estimate: MemoryEstimate) -> str:
    """The estimate as one line (for the log), the program itself included."""
    counted = MemoryEstimate(estimate.merged() + (program_part(),))
    return f"estimated memory {format_bytes(counted.total)}: " + ", ".join(
        f"{p.what} {format_bytes(p.nbytes)}" for p in counted.parts if p.nbytes)
