"""Finished runs as reports see them: a name, the typed metrics, overrides, the published
numbers they are compared with.

A run's files are read as :mod:`nlosfw.report.inputs` reads them (regular files inside the
reported folder, bounded), and every text in them is cut to
:data:`~nlosfw.common.text.MAX_SHOWN` characters: a record holds only what a report can
show.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import yaml

from nlosfw.common import yaml_safe
from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.common.files import is_regular_file
from nlosfw.common.text import shortened_data
from nlosfw.pipeline.metrics import RunMetrics
from nlosfw.pipeline.settings import PublishedTable
from nlosfw.report.inputs import read_inside


@dataclass(frozen=True)
class RunRecord:
    """One run: its name (the run directory relative to the report's root), its metrics,
    the command-line overrides that made it and the published numbers it is compared with."""

    name: str
    metrics: RunMetrics
    overrides: tuple[str, ...] = ()
    published: Mapping[str, PublishedTable] = field(default_factory=dict)
    """The run's ``published`` tables (published numbers), by name, if any."""
    config: Mapping[str, object] = field(default_factory=dict)
    """The run's resolved configuration (its config.yaml), if it has one."""


def find_runs(root: Path) -> list[Path]:
    """Every run directory (one holding metrics.json) under ``root``, sorted."""
    return sorted({p.parent for p in root.rglob("metrics.json")
                   if "interrupted-" not in str(p.relative_to(root)) and is_regular_file(p)})


def read_run(run_dir: Path, root: Path) -> RunRecord:
    """The record of the run in ``run_dir``, reading only regular files inside ``root``; a
    one-line :class:`DataError` names a file that cannot be read (a link leaving ``root``,
    an oversized, unreadable or older metrics.json, a broken config)."""
    path = run_dir / "metrics.json"
    try:
        data = msgspec.json.decode(read_inside(path, root))
    except msgspec.DecodeError as err:
        raise DataError(f"{path}: unreadable ({err})") from None
    metrics = RunMetrics.from_json(shortened_data(data), where=str(path))
    overrides = _yaml(run_dir / ".hydra" / "overrides.yaml", root) or []
    config = _yaml(run_dir / "config.yaml", root) or {}
    if not isinstance(overrides, list) or not isinstance(config, dict):
        raise DataError(f"{run_dir}: .hydra/overrides.yaml must hold a list and config.yaml "
                        "a mapping")
    return RunRecord(name=str(run_dir.relative_to(root)) or ".", metrics=metrics,
                     overrides=tuple(str(o) for o in overrides),
                     published=_published(config, run_dir / "config.yaml"), config=config)


def _published(config: Mapping[str, object], where: Path) -> dict[str, PublishedTable]:
    """The ``published`` tables of a run's config; a one-line DataError naming ``where``
    when they are malformed. (The ``thesis`` numbers of runs made before there were
    published tables are not read.)"""
    node = config.get("published") or {}
    try:
        if not isinstance(node, Mapping):
            raise ConfigError("published", f"must be a mapping of tables, got {node!r}")
        return {str(name): config_from_mapping(PublishedTable, table, f"published.{name}")
                for name, table in node.items()}
    except ConfigError as err:
        raise DataError(f"{where}: {err}") from None


def _yaml(path: Path, root: Path) -> Any:
    """The YAML data of ``path`` (None when there is no such file), its texts shortened."""
    if not path.exists() and not path.is_symlink():
        return None
    text = read_inside(path, root)
    try:
        return shortened_data(yaml_safe.load(text.decode("utf-8")))  # bounded: no alias bombs
    except (UnicodeDecodeError, yaml.YAMLError) as err:
        raise DataError(f"{path}: unreadable ({' '.join(str(err).split())})") from None
