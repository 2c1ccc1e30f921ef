"""The summary table printed at the end of a run (from its :class:`RunMetrics`)."""

from __future__ import annotations

import msgspec
from rich.table import Table
from rich.text import Text

from nlosfw.common.config import Scalar
from nlosfw.common.text import visible
from nlosfw.pipeline.metrics import RunMetrics


def _fmt(value: Scalar, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) < 1e4 else f"{value:.3e}"
    return str(value)


def _add(table: Table, *cells: str) -> None:
    """A row of plain text: file and scene names are shown as they are, never as markup,
    with control characters made visible."""
    table.add_row(*(Text(visible(cell)) for cell in cells))


def summary_table(metrics: RunMetrics) -> Table:
    """The capture (scene or file, and its preprocessing), field errors per model and split,
    reconstruction scores per source, stage timings."""
    table = Table(title="nlosfw run summary", title_justify="left", show_lines=False)
    table.add_column("section", style="cyan")
    table.add_column("item", style="bold")
    table.add_column("values")
    run = metrics.run
    if run.capture_file is not None:
        _add(table, "capture", "file", f"{run.capture_file} (format {run.capture_format or '?'})")
    else:
        _add(table, "capture", "scene", f"{run.scene} (simulator {run.simulator})")
    for step in () if metrics.capture is None else metrics.capture.preprocessing:
        origin = {"format": " (format default)", "automatic": " (automatic)"}.get(step.source, "")
        _add(table, "", f"  {step.option}{origin}", step.effect)
    for source, entry in (metrics.field or {}).items():
        _add(table, "field model", f"{source} ({entry.plugin})",
                      f"params {entry.n_parameters}, fit {_fmt(entry.fit.seconds)} s,"
                      f" predict {_fmt(entry.predict_seconds)} s")
        if entry.splits is None:
            continue
        for split, values in entry.splits.by_set().items():
            _add(table, "", f"  {split}",
                          f"NMSE {_fmt(values.nmse_db)} dB, "
                          f"rel. L2 {_fmt(values.relative_l2)}, "
                          f"amp. RMSE {_fmt(values.amplitude_rmse)}, "
                          f"phase err. {_fmt(values.phase_error)} rad")
    rec = metrics.reconstruction
    sources = {} if rec is None else rec.sources
    for source, scores in sources.items():
        depth = ("" if scores.depth_rmse_m is None
                 else f", depth RMSE {_fmt(scores.depth_rmse_m)} m")
        if rec is not None and list(sources) == ["true"]:  # model=none: nothing to compare
            _add(table, "reconstruction", f"capture ({rec.imager})",
                          f"{rec.depth_planes} planes, z = {_fmt(min(rec.depths))}-"
                          f"{_fmt(max(rec.depths))} m{depth}; {_fmt(scores.seconds)} s")
            continue
        _add(table, "reconstruction", f"{source} vs true",
                      f"PSNR {_fmt(scores.psnr)} dB, SSIM {_fmt(scores.ssim)}, "
                      f"RMSE {_fmt(scores.rmse)}; volume PSNR {_fmt(scores.volume_psnr)} dB, "
                      f"SSIM {_fmt(scores.volume_ssim)}{depth}; {_fmt(scores.seconds)} s")
    timings = {k: v for k, v in msgspec.structs.asdict(metrics.timings).items() if v is not None}
    _add(table, "timings", "stages (s)", ", ".join(f"{k} {_fmt(v)}" for k, v in timings.items()))
    return table
