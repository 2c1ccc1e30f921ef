"""Collecting a study that runs as Hydra sweeps: every run's metrics.json read through
``nlosfw.report`` (``find_runs``, ``read_run``, ``study_rows``: the scores the runs
recorded, grouped over seeds), what ran (the sweeps' overrides) and the fit times.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nlosfw.report import RunRecord, Stat, StudyRow, find_runs, read_run, study_rows


def collect_study(dirs: Sequence[Path]) -> dict[str, Any]:
    """The study's rows (aggregated over seeds) and what ran, from the runs under ``dirs``."""
    records: list[RunRecord] = []
    for root in dirs:
        records += [read_run(run, root) for run in find_runs(root)]
    rows = study_rows(records)
    completed = [r for r in records if r.metrics.status == "completed"]
    return {
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "machine": {"platform": platform.platform(), "python": platform.python_version(),
                    "cpus": os.cpu_count()},
        "sweeps": [str(d) for d in dirs],
        "runs": len(records), "completed": len(completed),
        "overrides": _common_overrides(completed),
        "fit_seconds": _fit_seconds(completed),
        "rows": [row.to_json() for row in rows],
    }


def _common_overrides(records: Sequence[RunRecord]) -> dict[str, list[str]]:
    """Every override key of the runs with the values it took (the sweep's axes)."""
    values: dict[str, set[str]] = {}
    for record in records:
        for override in record.overrides:
            key, _, value = override.partition("=")
            values.setdefault(key, set()).add(value)
    return {key: sorted(v) for key, v in sorted(values.items())}


def _fit_seconds(records: Sequence[RunRecord]) -> dict[str, dict[str, float]]:
    """Fit time of each model plugin: mean and maximum over its runs (seconds)."""
    times: dict[str, list[float]] = {}
    for record in records:
        entry = record.metrics.field_entry("model")
        if entry is not None:
            times.setdefault(entry.plugin, []).append(entry.fit.seconds)
    return {name: {"mean": round(sum(t) / len(t), 2), "max": round(max(t), 2), "runs": len(t)}
            for name, t in sorted(times.items())}


#: Every score a study row may carry: rows collected before a score existed lack it.
SCORES = ("heldout_excess_db", "heldout_nmse_db", "heldout_floor_db", "psnr", "ssim",
          "scale_invariant_psnr", "front_view_gain", "volume_psnr", "volume_ssim",
          "depth_rmse_m")


def study_rows_of(results: dict[str, Any]) -> list[StudyRow]:
    """The collected rows as ``nlosfw.report.StudyRow`` (for its tables and figure), a
    score the row lacks as a score no run has."""
    return [StudyRow(condition=r["condition"], pattern=r["pattern"],
                     undersampling=r["undersampling"], train_samples=r["train_samples"],
                     series=r["series"], kind=r["kind"], runs=r["runs"], seeds=tuple(r["seeds"]),
                     scores={**{k: Stat.of([]) for k in SCORES},
                             **{k: Stat(**v) for k, v in r["scores"].items()}})
            for r in results["rows"]]


def fmt(stat: Stat, digits: int, scale: float = 1.0) -> str:
    """A mean, with ``± std`` when it has several values that differ; ``-`` when absent."""
    if stat.mean is None:
        return "-"
    text = f"{stat.mean * scale:.{digits}f}"
    if stat.n > 1 and stat.std:
        text += f" ± {stat.std * scale:.{digits}f}"
    return text
