"""The memory this process can still allocate: what the run's memory estimate and the size
check of a file's datasets (:mod:`nlosfw.common.hdf5_guard`) compare with; and the types
of a memory estimate (:class:`MemoryEstimate` of :class:`MemoryPart`, computed from a
:class:`PlanShape`), which the run's plan sums from the engine's own arrays and the
estimates the plugins give of themselves."""

from __future__ import annotations

import contextlib
import math
import os
from dataclasses import dataclass
from pathlib import Path


def available_memory() -> int | None:
    """Bytes of memory this process can still allocate (MemAvailable, within the cgroup's
    limit when there is one), or None when unknown."""
    found = []
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    cgroup = _cgroup_room()
    if cgroup is not None:
        found.append(cgroup)
    if not found and hasattr(os, "sysconf"):
        with contextlib.suppress(ValueError, OSError):
            found.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    return min(found) if found else None


def _cgroup_room() -> int | None:
    """limit - usage of the cgroup (v2, else v1), or None without a limit."""
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            limit = Path(limit_file).read_text().strip()
            usage = int(Path(usage_file).read_text().strip())
        except (OSError, ValueError):
            continue
        if limit == "max" or int(limit) >= 1 << 60:
            return None
        return max(0, int(limit) - usage)
    return None


@dataclass(frozen=True)
class MemoryPart:
    """One part of a memory estimate: what it holds, why it is that large (one line: the
    sizes and options behind it), its bytes. Parts with the same non-empty ``once`` key are
    the same memory (a backend's runtime, whichever model loads it): a run counts the
    largest of them once."""

    what: str
    why: str
    nbytes: float
    once: str = ""

    def __post_init__(self) -> None:
        if not (isinstance(self.nbytes, (int, float)) and math.isfinite(self.nbytes)
                and self.nbytes >= 0):
            raise ValueError(f"memory part {self.what!r}: bytes must be finite and >= 0, "
                             f"got {self.nbytes!r}")
        if "\n" in self.what or "\n" in self.why or not self.what:
            raise ValueError(f"memory part {self.what!r}: what and why are one line each")


@dataclass(frozen=True)
class MemoryEstimate:
    """The memory something a run does holds at its peak, in named parts (an empty
    estimate: nothing beyond what the engine counts itself)."""

    parts: tuple[MemoryPart, ...] = ()

    @property
    def total(self) -> float:
        """The bytes of the parts, each ``once`` key counted once (its largest part)."""
        return float(sum(part.nbytes for part in self.merged()))

    def __add__(self, other: MemoryEstimate) -> MemoryEstimate:
        return MemoryEstimate(self.parts + other.parts)

    def merged(self) -> tuple[MemoryPart, ...]:
        """The parts as a run counts them: of each ``once`` key its largest part only."""
        largest: dict[str, MemoryPart] = {}
        for part in self.parts:
            if part.once and (part.once not in largest
                              or part.nbytes > largest[part.once].nbytes):
                largest[part.once] = part
        return tuple(p for p in self.parts if not p.once or largest[p.once] is p)


@dataclass(frozen=True)
class PlanShape:
    """The sizes of a run as its plan knows them before any array is allocated: what a
    plugin's memory estimate is computed from (``None``: not known yet; a capture file's
    geometry is known once it is read, its header's sizes before).

    The transient has ``bins`` time bins of ``sensors`` × ``lasers`` samples; the wall
    grid is ``grid`` (ny, nx) with ``spacing`` (m) between points; the phasor field holds
    ``frequencies`` frequencies from ``f_min`` to ``f_max`` (cycles/m); the models train
    on ``training_frequencies`` of them and on the grid ``training`` (ny, nx) of its wall
    points, ``step`` wall spacings apart (a random pattern's points lie scattered on the
    whole grid: ``training`` is ``grid``, ``step`` 1); the hidden scene lies within
    ``depth_range`` (m), at most ``deepest`` (m, half the time span) away."""

    bins: int
    sensors: int
    lasers: int = 1
    grid: tuple[int, int] | None = None
    spacing: float | None = None
    confocal: bool = False
    frequencies: int = 1
    f_min: float | None = None
    f_max: float | None = None
    training_frequencies: int = 1
    training: tuple[int, int] | None = None
    step: int = 1
    depth_range: tuple[float, float] | None = None
    deepest: float | None = None

    @property
    def samples(self) -> float:
        """The field's values: frequencies × sensors × lasers."""
        return float(self.frequencies) * self.sensors * self.lasers

    @property
    def square_grid(self) -> tuple[int, int]:
        """``grid``, or the smallest square grid of ``sensors`` points when it is unknown."""
        if self.grid is not None:
            return self.grid
        side = max(1, math.isqrt(max(self.sensors - 1, 0)) + 1)
        return side, side
