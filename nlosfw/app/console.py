"""Terminal output of the app: rich logging, the config tree, progress bars."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

from rich.console import Console
from rich.logging import RichHandler
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.tree import Tree


def rich_log_handler() -> logging.Handler:
    """The console handler of the run log (used by conf/hydra/job_logging/nlosfw.yaml)."""
    return RichHandler(show_path=False, rich_tracebacks=False, markup=False,
                       log_time_format="[%X]")


def config_tree(config: Mapping[str, Any], title: str = "config") -> Tree:
    """A rich tree of a (plain) configuration mapping."""
    tree = Tree(f"[bold]{title}[/]")

    def add(node: Tree, value: Any) -> None:
        for key, item in value.items():
            if isinstance(item, Mapping) and item:
                add(node.add(f"[cyan]{key}[/]"), item)
            elif isinstance(item, list) and item and all(isinstance(i, Mapping) for i in item):
                branch = node.add(f"[cyan]{key}[/]")
                for i, entry in enumerate(item):
                    add(branch.add(f"[{i}]"), entry)
            else:
                node.add(f"[cyan]{key}[/]: {item}")

    add(tree, config)
    return tree


def progress_bar(console: Console | None = None) -> Progress:
    """A progress display with a loss field (``task.fields['info']``)."""
    return Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    )
