"""``python -m nlosfw --help``: a short page whose every example command is valid."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from nlosfw import compose
from nlosfw.cli import help as help_page
from nlosfw.cli import main
from nlosfw.common.resources import config_dir
from nlosfw.pipeline.settings import RunSettings
from nlosfw.plugins import PluginKind, load_plugins


@pytest.fixture()
def page(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert not (tmp_path / "outputs").exists()
    return out


def _section(page: str, title: str) -> list[str]:
    """The indented lines of the section whose title starts with ``title`` (up to the
    next blank line; an unindented line right after the title continues the title)."""
    lines = page.splitlines()
    index = next(i for i, line in enumerate(lines) if line.startswith(title)) + 1
    while index < len(lines) and lines[index] and not lines[index].startswith(" "):
        index += 1
    out = []
    while index < len(lines) and lines[index].strip():
        out.append(lines[index])
        index += 1
    return out


def test_the_page_is_short_and_fits_100_columns(page):
    lines = page.splitlines()
    assert len(lines) <= 70, len(lines)
    assert max(len(line) for line in lines) <= 100
    assert "Hydra" not in page.split("more")[0]       # not Hydra's dump


def test_the_page_lists_every_subcommand(page):
    usage = "\n".join(_section(page, "usage"))
    for command in ("python -m nlosfw [OVERRIDE ...]", "python -m nlosfw -m OVERRIDE ...",
                    "python -m nlosfw plugins [NAME]", "python -m nlosfw plugins --check",
                    "python -m nlosfw report DIR", "python -m nlosfw.testing NAME"):
        assert command in usage
    assert "python -m nlosfw -cn NAME -m      a sweep preset: reproduce, thesis_table4_1, " \
           "thesis_table5_1" in usage
    assert "python -m nlosfw --hydra-help" in page and "python -m nlosfw --cfg job" in page


def test_every_config_group_has_one_entry_with_its_choices(page):
    groups = " ".join(" ".join(_section(page, "config groups")).split())
    host = load_plugins()
    for kind in PluginKind:
        names = host.registry.names(kind)
        entry = groups.split(f" {kind.value} ", 1)[1]
        listed = re.split(r",\s*", entry.split(": ", 1)[1].split(" experiment ")[0])
        for name in names:
            assert any(item.startswith(name) for item in listed), (kind, name, entry)
    assert "siren_torch (default)" in groups and "thesis_two_planes (default)" in groups
    assert "analytic (default)" in groups and "fft (default)" in groups
    conf = config_dir()
    for scene in (p.stem for p in (conf / "scene").glob("*.yaml")):
        assert scene in groups
    for preset in (p.stem for p in (conf / "experiment").glob("*.yaml")):
        assert preset in groups
    # the settings groups: their one line comes from RunSettings' own docstrings
    assert "split.* which wall samples and frequencies the field models train on " \
           "(spatial_step, pattern, spatial_fraction, seed, spectral, spectral_fraction, " \
           "count_splitting, count_splitting_seed)" in groups
    assert "output.* which large files the run writes, and whether it may replace an " \
           "earlier run's (keep, compression, overwrite)" in groups
    for acquisition in ("clean", "noisy"):
        assert acquisition in groups
    from dataclasses import fields

    for f in fields(RunSettings):
        if f.name != "published":
            assert f" {f.name}" in groups, f.name


def _examples(page: str) -> list[str]:
    return [line.strip() for line in _section(page, "examples")
            if line.strip().startswith("python -m nlosfw")]


def test_five_examples_and_each_one_is_a_valid_command(page, tmp_path, monkeypatch):
    examples = _examples(page)
    assert examples == [command for command, _ in help_page.EXAMPLES]
    assert len(examples) == 5
    host = load_plugins()
    compose.register_configs(host)
    compose.ensure_resolvers()
    monkeypatch.chdir(tmp_path)
    for command in examples:
        argv = compose.normalise_overrides(shlex.split(command)[3:])
        if any(name in argv for name in ("embree",)):
            pytest.importorskip("embreex")
        named = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("-cn", "--config-name")]
        overrides = [a for a in argv if not a.startswith("-") and a not in named]
        # composes and validates as a run would, before any output
        compose.preflight(overrides, host, named[0] if named else "config",
                          multirun="-m" in argv or "--multirun" in argv)
    assert not (tmp_path / "outputs").exists()


def test_help_wins_over_overrides_and_hydra_help_stays_reachable(capsys):
    assert main(["model=interp", "--help"]) == 0
    assert capsys.readouterr().out.startswith("nlosfw ")
    assert main(["-h"]) == 0
    assert "config groups" in capsys.readouterr().out
    assert main(["--hydra-help"]) == 0            # Hydra's exit status, not an exception
    out = capsys.readouterr().out
    assert out.startswith("Hydra (") and "== Flags ==" in out


def test_the_documentation_named_exists():
    root = Path(__file__).resolve().parents[2]
    for name in re.findall(r"[\w/]+\.md", help_page.DOCS):
        assert (root / name).is_file(), name
