"""``python -m nlosfw report DIR``: aggregate every run under DIR (a sweep) into one report.

Writes ``report.csv`` (one row per run), ``report.md`` (the same as a markdown
table, plus thesis comparison tables when presets carry reference numbers) and
``report.png`` (held-out field error and reconstruction SSIM per run, model
against the interp baseline) into ``DIR/report/`` (or ``report-2``, ... if that
exists: earlier reports are never overwritten).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml
from rich.console import Console
from rich.table import Table

from nlosfw.app.tables import markdown_table
from nlosfw.app.thesis import thesis_comparison
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.common.files import atomic_path, write_text

log = logging.getLogger(__name__)

#: Columns of the report, in order: (column name, path into the run record).
COLUMNS = (
    ("run", ("run",)),
    ("status", ("status",)),
    ("scene", ("scene",)),
    ("simulator", ("simulator",)),
    ("model", ("model",)),
    ("imager", ("imager",)),
    ("overrides", ("overrides",)),
    ("n_parameters", ("field", "model", "n_parameters")),
    ("parameters_per_value", ("field", "model", "parameters_per_value")),
    ("fit_seconds", ("field", "model", "fit", "seconds")),
    ("final_loss", ("field", "model", "fit", "final_loss")),
    ("model_heldout_pixels_nmse_db", ("field", "model", "splits", "heldout_pixels", "nmse_db")),
    ("model_heldout_freqs_nmse_db",
     ("field", "model", "splits", "heldout_frequencies", "nmse_db")),
    ("model_all_nmse_db", ("field", "model", "splits", "all", "nmse_db")),
    ("interp_heldout_pixels_nmse_db",
     ("field", "interp", "splits", "heldout_pixels", "nmse_db")),
    ("interp_heldout_freqs_nmse_db",
     ("field", "interp", "splits", "heldout_frequencies", "nmse_db")),
    ("interp_all_nmse_db", ("field", "interp", "splits", "all", "nmse_db")),
    ("model_ssim", ("reconstruction", "sources", "model", "ssim")),
    ("interp_ssim", ("reconstruction", "sources", "interp", "ssim")),
    ("raw_ssim", ("reconstruction", "sources", "raw", "ssim")),
    ("model_psnr", ("reconstruction", "sources", "model", "psnr")),
    ("interp_psnr", ("reconstruction", "sources", "interp", "psnr")),
    ("total_seconds", ("timings", "total")),
)


def find_runs(root: Path) -> list[Path]:
    """Every run directory (one holding metrics.json) under ``root``, sorted."""
    return sorted({p.parent for p in root.rglob("metrics.json")
                   if "interrupted-" not in str(p.relative_to(root))})


def run_record(run_dir: Path, root: Path) -> dict[str, Any]:
    """The metrics of one run, flattened with its selected plugins and overrides."""
    try:
        metrics = json.loads((run_dir / "metrics.json").read_text())
    except (OSError, ValueError) as err:
        raise DataError(f"{run_dir / 'metrics.json'}: unreadable ({err})") from None
    info = metrics.get("run") or {}
    overrides_file = run_dir / ".hydra" / "overrides.yaml"
    overrides = yaml.safe_load(overrides_file.read_text()) if overrides_file.exists() else []
    return {
        **metrics,
        "run": str(run_dir.relative_to(root)) or ".",
        "scene": info.get("scene"),
        "simulator": info.get("simulator"),
        "model": info.get("model"),
        "imager": info.get("imager"),
        "overrides": " ".join(overrides or []),
        "thesis": _thesis_of(run_dir),
    }


def _thesis_of(run_dir: Path) -> dict[str, Any]:
    config = run_dir / "config.yaml"
    if not config.exists():
        return {}
    return (yaml.safe_load(config.read_text()) or {}).get("thesis") or {}


def _get(record: dict[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = record
    for key in path:
        if not isinstance(value, dict):
            return None
        value = value.get(key)
    return value


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def report_rows(records: list[dict[str, Any]]) -> list[dict[str, str]]:
    return [{name: _fmt(_get(r, path)) for name, path in COLUMNS} for r in records]


def to_csv(rows: list[dict[str, str]]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=[c for c, _ in COLUMNS])
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def to_markdown(rows: list[dict[str, str]], columns: Sequence[str] | None = None) -> str:
    columns = list(columns or [c for c, _ in COLUMNS])
    return markdown_table(columns, [[row.get(c, "") for c in columns] for row in rows])


def comparison_figure(records: list[dict[str, Any]], path: Path) -> None:
    """Held-out NMSE (model vs interp) and reconstruction SSIM per run, as a PNG."""
    import numpy as np
    from matplotlib.figure import Figure

    labels = [f"{r['run']}\n{r.get('model') or ''}" for r in records]
    x = np.arange(len(records))

    def series(path: tuple[str, ...]) -> np.ndarray:
        return np.array([_get(r, path) if _get(r, path) is not None else np.nan
                         for r in records], dtype=float)

    fig = Figure(figsize=(max(8, 1.2 * len(records) + 4), 4.5))
    axes = fig.subplots(1, 2)
    width = 0.38
    for offset, source in ((-width / 2, "model"), (width / 2, "interp")):
        axes[0].bar(x + offset, series(("field", source, "splits", "heldout_pixels", "nmse_db")),
                    width, label=source)
        axes[1].bar(x + offset, series(("reconstruction", "sources", source, "ssim")), width,
                    label=source)
    axes[0].set_ylabel("held-out pixels NMSE (dB, lower is better)")
    axes[1].set_ylabel("reconstruction SSIM vs true field (higher is better)")
    for ax in axes:
        ax.set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
        ax.legend()
        ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")


def _free_dir(root: Path) -> Path:
    target = root / "report"
    n = 2
    while target.exists():
        target = root / f"report-{n}"
        n += 1
    return target


def write_report(root: Path) -> tuple[Path, list[dict[str, str]]]:
    """Write report.csv, report.md, report.png for the runs under ``root``; return the dir."""
    runs = find_runs(root)
    if not runs:
        raise DataError(f"{root}: holds no run (no metrics.json below it)")
    records = [run_record(r, root) for r in runs]
    rows = report_rows(records)
    out = _free_dir(root)
    out.mkdir(parents=True)
    write_text(out / "report.csv", to_csv(rows))
    markdown = f"# nlosfw report: {root}\n\n{len(rows)} runs.\n\n" + to_markdown(rows)
    tables = thesis_comparison(records)
    if tables:
        markdown += "\n## Next to the thesis\n\n" + tables
    write_text(out / "report.md", markdown)
    with atomic_path(out / "report.png") as tmp:
        comparison_figure(records, tmp)
    return out, rows


def report_command(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m nlosfw report",
                                     description="Aggregate the runs of a sweep directory.")
    parser.add_argument("directory", help="a sweep (multirun) directory or any parent of runs")
    args = parser.parse_args(list(argv))
    root = Path(args.directory).expanduser()
    if not root.is_dir():
        raise ConfigError("directory", f"{root} is not a directory")
    out, rows = write_report(root)
    console = Console()
    table = Table(title=f"{len(rows)} runs under {root}", title_justify="left")
    shown = ("run", "status", "scene", "model", "model_heldout_pixels_nmse_db",
             "interp_heldout_pixels_nmse_db", "model_ssim", "interp_ssim", "fit_seconds")
    for column in shown:
        table.add_column(column)
    for row in rows:
        table.add_row(*(row[c] for c in shown))
    console.print(table)
    console.print(f"report written to {out}")
    return 0
