"""``python -m nlosfw report DIR``: aggregate every run under DIR (a sweep) into one
report (:func:`nlosfw.report.write_report`), and show its rows as a table."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.table import Table

from nlosfw.common.errors import ConfigError
from nlosfw.common.text import console_text as escape
from nlosfw.report import write_report


def report_command(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m nlosfw report",
                                     description="Aggregate the runs of a sweep directory.")
    parser.add_argument("directory", help="a sweep (multirun) directory or any parent of runs")
    parser.add_argument("--x", metavar="KEY", default=None,
                        help="the swept override on the quality plot's x axis (default: the "
                             "numeric swept key with the most values, else another swept key)")
    args = parser.parse_args(list(argv))
    root = Path(args.directory).expanduser()
    if not root.is_dir():
        raise ConfigError("directory", f"{root} is not a directory")
    out, rows = write_report(root, args.x)
    console = Console()
    table = Table(title=f"{len(rows)} runs under {escape(str(root))}", title_justify="left")
    shown = ("run", "status", "scene", "model", "seed", "undersampling", "raw_psnr",
             "interp_psnr", "model_psnr", "raw_ssim", "interp_ssim", "model_ssim",
             "fit_seconds")
    for column in shown:
        table.add_column(column)
    for row in rows:
        table.add_row(*(escape(row[c]) for c in shown))
    console.print(table)
    console.print(f"report written to {escape(str(out))}", highlight=False)
    return 0
