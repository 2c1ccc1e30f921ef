"""Finished runs as reports see them: a name, the typed metrics, overrides, thesis numbers."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from nlosfw.common import yaml_safe
from nlosfw.common.errors import DataError
from nlosfw.common.files import is_regular_file
from nlosfw.pipeline.metrics import RunMetrics


@dataclass(frozen=True)
class RunRecord:
    """One run: its name (the run directory relative to the report's root), its metrics,
    the command-line overrides that made it and its ``thesis`` reference numbers."""

    name: str
    metrics: RunMetrics
    overrides: tuple[str, ...] = ()
    thesis: Mapping[str, Any] = field(default_factory=dict)
    """The run's ``thesis`` config (reference values of a thesis preset), if any."""


def find_runs(root: Path) -> list[Path]:
    """Every run directory (one holding metrics.json) under ``root``, sorted."""
    return sorted({p.parent for p in root.rglob("metrics.json")
                   if "interrupted-" not in str(p.relative_to(root)) and is_regular_file(p)})


def read_run(run_dir: Path, root: Path) -> RunRecord:
    """The record of the run in ``run_dir``; a one-line :class:`DataError` names a file
    that cannot be read (an unreadable or older metrics.json, a broken config)."""
    metrics = RunMetrics.read(run_dir / "metrics.json")
    overrides = _yaml(run_dir / ".hydra" / "overrides.yaml") or []
    config = _yaml(run_dir / "config.yaml") or {}
    if not isinstance(overrides, list) or not isinstance(config, dict):
        raise DataError(f"{run_dir}: .hydra/overrides.yaml must hold a list and config.yaml "
                        "a mapping")
    return RunRecord(name=str(run_dir.relative_to(root)) or ".", metrics=metrics,
                     overrides=tuple(str(o) for o in overrides),
                     thesis=config.get("thesis") or {})


def _yaml(path: Path) -> Any:
    if not path.exists():
        return None
    if not is_regular_file(path):  # a FIFO would block the read
        raise DataError(f"{path}: not a regular file; it is not read")
    try:
        return yaml_safe.load(path.read_text(encoding="utf-8"))  # bounded: no alias bombs
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise DataError(f"{path}: unreadable ({' '.join(str(err).split())})") from None
