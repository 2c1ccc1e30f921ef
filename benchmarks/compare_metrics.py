"""Compare two runs' metrics.json: every number equal (floats exactly), apart from what is
documented to differ between two runs of one configuration.

    python benchmarks/compare_metrics.py BEFORE/metrics.json AFTER/metrics.json [...]

Pairs of files (before, after) in order. Left out of the comparison: the timings
(:data:`nlosfw.pipeline.metrics.TIMING_FIELDS`, through
:func:`~nlosfw.pipeline.metrics.without_timings`), ``run.started``, ``run.dir``,
``run.config_hash`` and ``run.nlosfw_version`` (where and when and by which version the
run ran), ``schema_version``, and the fields a newer schema adds (present in one file only
and listed in :data:`ADDED`); an older file is read as the current schema reads it, its
renamed keys (``capture.thinning``) under their new names. Each difference is printed as
its dotted path and both values; the exit status is 0 when every pair agrees, 1 otherwise,
2 for a file that cannot be read.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

#: Fields of ``run`` that differ between any two runs of one configuration.
RUN_FIELDS = ("started", "dir", "config_hash", "nlosfw_version")
#: Fields a newer metrics.json adds (compared only where both files hold them), by name at
#: any depth.
ADDED = ("null_reasons",)


def comparable(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` as the current schema reads it (an older file's renamed keys under their
    new names), without the timings, ``schema_version`` and the run's own fields."""
    from nlosfw.pipeline import SCHEMA_VERSION, metrics_as_current, without_timings

    out = without_timings(metrics_as_current(dict(data), SCHEMA_VERSION))
    out.pop("schema_version", None)
    run = dict(out.get("run") or {})
    for name in RUN_FIELDS:
        run.pop(name, None)
    out["run"] = run
    return out


def differences(before: Any, after: Any, path: str = "") -> list[str]:
    """The dotted paths where ``before`` and ``after`` differ, with both values."""
    if isinstance(before, Mapping) and isinstance(after, Mapping):
        found = []
        for key in sorted(set(before) | set(after)):
            where = f"{path}.{key}" if path else str(key)
            if key not in before or key not in after:
                if key not in ADDED:
                    side = "after" if key in after else "before"
                    found.append(f"{where}: only {side} holds it")
                continue
            found += differences(before[key], after[key], where)
        return found
    if isinstance(before, list) and isinstance(after, list):
        if len(before) != len(after):
            return [f"{path}: {len(before)} items before, {len(after)} after"]
        return [d for i, (b, a) in enumerate(zip(before, after, strict=True))
                for d in differences(b, a, f"{path}[{i}]")]
    if before != after or type(before) is not type(after):
        return [f"{path}: {before!r} before, {after!r} after"]
    return []


def compare(before: Path, after: Path) -> list[str]:
    """The differences between two metrics.json files (see the module's documentation)."""
    old, new = (json.loads(p.read_text(encoding="utf-8")) for p in (before, after))
    return differences(comparable(old), comparable(new))


def main(argv: list[str]) -> int:
    if not argv or len(argv) % 2:
        sys.stderr.write(__doc__.splitlines()[3].strip() + "\n")
        return 2
    status = 0
    for before, after in zip(argv[::2], argv[1::2], strict=True):
        try:
            found = compare(Path(before), Path(after))
        except (OSError, ValueError) as err:
            sys.stderr.write(f"error: {err}\n")
            return 2
        print(f"{before} vs {after}: " + ("equal" if not found else
                                           f"{len(found)} differences"))
        for line in found:
            print(f"  {line}")
        status |= bool(found)
    return status


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
