"""The summary table printed at the end of a run (from the metrics dict)."""

from __future__ import annotations

from typing import Any

from rich.table import Table


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) < 1e4 else f"{value:.3e}"
    return str(value)


def summary_table(metrics: dict[str, Any]) -> Table:
    """Field errors per model and split, reconstruction scores per source, stage timings."""
    table = Table(title="nlosfw run summary", title_justify="left", show_lines=False)
    table.add_column("section", style="cyan")
    table.add_column("item", style="bold")
    table.add_column("values")
    for source, entry in (metrics.get("field") or {}).items():
        table.add_row("field model", f"{source} ({entry.get('plugin')})",
                      f"params {entry.get('n_parameters')}, fit {_fmt(entry['fit']['seconds'])} s,"
                      f" predict {_fmt(entry.get('predict_seconds'))} s")
        for split, values in (entry.get("splits") or {}).items():
            table.add_row("", f"  {split}",
                          f"NMSE {_fmt(values.get('nmse_db'))} dB, "
                          f"rel. L2 {_fmt(values.get('relative_l2'))}, "
                          f"amp. RMSE {_fmt(values.get('amplitude_rmse'))}, "
                          f"phase err. {_fmt(values.get('phase_error'))} rad")
    recon = metrics.get("reconstruction") or {}
    for source, values in (recon.get("sources") or {}).items():
        table.add_row("reconstruction", f"{source} vs true",
                      f"SSIM {_fmt(values.get('ssim'))}, PSNR {_fmt(values.get('psnr'))} dB, "
                      f"RMSE {_fmt(values.get('rmse'))}, {_fmt(values.get('seconds'))} s")
    timings = metrics.get("timings") or {}
    table.add_row("timings", "stages (s)", ", ".join(f"{k} {_fmt(v)}" for k, v in timings.items()))
    return table
