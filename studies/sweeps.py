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
    return _as_study_rows(results["rows"])


def paired_rows_of(results: dict[str, Any]) -> dict[tuple[str, str, float, str], StudyRow]:
    """The added runs' own rows of the sources the committed results already had (see
    :func:`add_runs`), by capture, pattern, sparsity and source."""
    rows = [r for addition in results.get("additions", []) for r in addition["paired_rows"]]
    return {(r.condition, r.pattern, float(r.undersampling), r.series): r
            for r in _as_study_rows(rows)}


def _as_study_rows(rows: Sequence[dict[str, Any]]) -> list[StudyRow]:
    return [StudyRow(condition=r["condition"], pattern=r["pattern"],
                     undersampling=r["undersampling"], train_samples=r["train_samples"],
                     series=r["series"], kind=r["kind"], runs=r["runs"], seeds=tuple(r["seeds"]),
                     scores={**{k: Stat.of([]) for k in SCORES},
                             **{k: Stat(**v) for k, v in r["scores"].items()}})
            for r in rows]


def fmt(stat: Stat, digits: int, scale: float = 1.0) -> str:
    """A mean, with ``± std`` when it has several values that differ; ``-`` when absent."""
    if stat.mean is None:
        return "-"
    text = f"{stat.mean * scale:.{digits}f}"
    if stat.n > 1 and stat.std:
        text += f" ± {stat.std * scale:.{digits}f}"
    return text


def add_runs(base: dict[str, Any], added: dict[str, Any]) -> dict[str, Any]:
    """``base`` (a study's committed results) with the runs collected in ``added``: the rows
    of series ``base`` lacks, and in ``base``'s own rows the scores they lack (a score its
    runs predate, taken from the added runs of the same capture, sparsity and source). Every
    number ``base`` has stays as it is; the sweeps, run counts, axes and fit times are both
    together, and ``additions`` says what was added, where and when. Runs of a sweep
    ``base`` already has are refused (SystemExit naming the folder): they would count twice."""
    again = sorted(set(base["sweeps"]) & set(added["sweeps"]))
    if again:
        raise SystemExit(f"{again[0]}: its runs are in the results already; collect only the "
                         "sweeps they lack")
    rows = [dict(r) for r in base["rows"]]
    index = {_row_key(r): i for i, r in enumerate(rows)}
    for row in added["rows"]:
        i = index.get(_row_key(row))
        if i is None:
            rows.append(row)
            continue
        scores = dict(rows[i]["scores"])
        for name, stat in row["scores"].items():
            if not scores.get(name, {}).get("n"):
                scores[name] = stat
        rows[i] = {**rows[i], "scores": scores}
    cells = {cell: n for n, cell in enumerate(dict.fromkeys(_row_key(r)[:3] for r in rows))}
    rows.sort(key=lambda r: cells[_row_key(r)[:3]])  # stable: a cell's added rows last
    axes = {key: sorted(set(base["overrides"].get(key, [])) | set(added["overrides"].get(key, [])))
            for key in sorted({*base["overrides"], *added["overrides"]})}
    fits = dict(base["fit_seconds"])
    for name, t in added["fit_seconds"].items():
        old = fits.get(name)
        fits[name] = t if old is None else {
            "mean": round((old["mean"] * old["runs"] + t["mean"] * t["runs"])
                          / (old["runs"] + t["runs"]), 2),
            "max": max(old["max"], t["max"]), "runs": old["runs"] + t["runs"]}
    series = sorted({r["series"] for r in added["rows"] if r["kind"] == "model"})
    # The added runs' own rows of what base already had (interp, the ceiling): scores
    # against the same runs, for comparisons a code change between the two would skew.
    paired = [r for r in added["rows"] if _row_key(r) in index]
    addition = {"series": series, "runs": added["runs"], "completed": added["completed"],
                "sweeps": added["sweeps"], "ran_on": added["ran_on"],
                "recorded": added["recorded"], "paired_rows": paired}
    joined = {key: f"{base['recorded'][key]}; added ({', '.join(series)}): "
                   f"{added['recorded'][key]}" for key in ("machine", "commit", "date")}
    return {**base, "recorded": joined, "sweeps": [*base["sweeps"], *added["sweeps"]],
            "runs": base["runs"] + added["runs"],
            "completed": base["completed"] + added["completed"], "overrides": axes,
            "fit_seconds": dict(sorted(fits.items())), "rows": rows,
            "ran_on": f"{base['ran_on']}; added: {', '.join(series)} on {added['ran_on']}",
            "additions": [*base.get("additions", []), addition]}


def withdraw_addition(results: dict[str, Any], series: Sequence[str]) -> dict[str, Any]:
    """``results`` without the runs an earlier :func:`add_runs` added for exactly ``series``
    (its rows, paired rows, sweeps, run counts, fit times and the text it joined to what
    ran where and when), e.g. before the runs of a changed default model are added in
    their place. No such addition: SystemExit naming the series."""
    wanted = sorted(series)
    found = [a for a in results.get("additions", []) if sorted(a["series"]) == wanted]
    if len(found) != 1:
        raise SystemExit(f"{', '.join(wanted)}: no one earlier addition of exactly these "
                         "series to replace")
    (old,) = found
    suffix = f"; added ({', '.join(old['series'])}): "
    recorded = {key: value.replace(suffix + old["recorded"][key], "")
                for key, value in results["recorded"].items()}
    gone = set(old["sweeps"])
    return {**results, "recorded": recorded,
            "sweeps": [s for s in results["sweeps"] if s not in gone],
            "runs": results["runs"] - old["runs"],
            "completed": results["completed"] - old["completed"],
            "fit_seconds": {k: v for k, v in results["fit_seconds"].items()
                            if k not in old["series"]},
            "rows": [r for r in results["rows"] if r["series"] not in old["series"]],
            "ran_on": results["ran_on"].replace(
                f"; added: {', '.join(old['series'])} on {old['ran_on']}", ""),
            "additions": [a for a in results["additions"] if a is not old]}


def shared_score_differences(base: dict[str, Any], added: dict[str, Any]) -> dict[str, float]:
    """The largest difference of each score's mean between the rows both have (the same
    capture, sparsity and source measured twice, e.g. ``interp`` in every run)."""
    mine = {_row_key(r): r for r in base["rows"]}
    found: dict[str, float] = {}
    for row in added["rows"]:
        other = mine.get(_row_key(row))
        if other is None:
            continue
        for name, stat in row["scores"].items():
            was = other["scores"].get(name, {}).get("mean")
            if stat.get("mean") is not None and was is not None:
                found[name] = max(found.get(name, 0.0), abs(stat["mean"] - was))
    return found


def _row_key(row: dict[str, Any]) -> tuple[str, str, float, str]:
    return (row["condition"], row["pattern"], float(row["undersampling"]), row["series"])
