"""Every plugin ``python -m nlosfw plugins`` lists has its page, with what it is, its options
(generated from its config dataclass), when to use it and its results; the generated pages,
the configuration reference and the nav are what ``python docs/gen_pages.py`` writes."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

from nlosfw.common.config_docs import option_docs
from nlosfw.plugins import load_plugins

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module      # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def gen():
    return _module("nlosfw_docs_gen_pages", DOCS / "gen_pages.py")


@pytest.fixture(scope="module")
def expected(gen):
    return gen.expected_files()


def test_the_generated_pages_are_up_to_date(gen, expected):
    stale = [str(path.relative_to(ROOT)) for path in gen.stale_files(expected)]
    assert not stale, f"out of date: {stale}; run: python docs/gen_pages.py"


def _sections(text: str) -> dict[str, str]:
    parts = re.split(r"^## (.+)$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def test_every_listed_plugin_has_a_page_with_its_sections():
    specs = load_plugins().registry.specs()
    kinds = {spec.kind.value for spec in specs}
    assert kinds == {"simulator", "transform", "model", "imager", "capture_format"}
    for spec in specs:
        page = DOCS / "plugins" / spec.kind.value / f"{spec.name}.md"
        assert page.is_file(), f"{spec.qualified_name} has no page {page.relative_to(ROOT)}"
        text = page.read_text()
        sections = _sections(text)
        assert list(sections) == ["What it is", "Options", "When to use it", "Results"], (
            f"{page.relative_to(ROOT)}: sections {list(sections)}")
        assert spec.description in sections["What it is"]
        options = sections["Options"]
        for option in option_docs(spec.config_class(), groups=True):
            name = option.name if spec.kind.value == "capture_format" else \
                f"{spec.kind.value}.{option.name}"
            assert f"| `{name}` |" in options, f"{page.name}: option {name} is not shown"
        results = sections["Results"].strip()
        assert results == "Not measured." or "README.md" in results or \
            "benchmarks/README.md" in results, f"{page.name}: results {results!r}"
        index = (DOCS / "plugins" / "index.md").read_text()
        assert f"({spec.kind.value}/{spec.name}.md)" in index


def test_a_changed_option_makes_its_page_stale(gen, expected, monkeypatch):
    """The check compares with the code: an option's new default is seen."""
    plugins = gen.installed_plugins()
    siren = next(p for p in plugins if p.name == "siren_torch")
    steps = next(o for o in siren.options if o.name == "steps")
    changed = siren.__class__(**{**siren.__dict__, "options": tuple(
        o if o is not steps else o.__class__(**{**o.__dict__, "default": 7})
        for o in siren.options)})
    notes = gen.yaml.safe_load(gen.NOTES.read_text())
    page = gen.plugin_page(changed, notes)
    assert "| `model.steps` | int | `7` |" in page
    path = DOCS / "plugins" / "model" / "siren_torch.md"
    assert gen.stale_files({**expected, path: page}) == [path]


def test_the_notes_name_only_studies_and_installed_plugins(gen, monkeypatch, tmp_path):
    hooks = _module("nlosfw_docs_hooks", DOCS / "hooks.py")
    assert hooks.STUDIES == gen.STUDIES
    notes = tmp_path / "notes.yaml"
    monkeypatch.setattr(gen, "NOTES", notes)
    notes.write_text("model:siren:\n  results:\n    - {text: x, study: my_study}\n")
    with pytest.raises(ValueError, match="unknown study 'my_study'"):
        gen.expected_files()
    notes.write_text("model:sirens:\n  what: x\n")
    with pytest.raises(ValueError, match=r"notes for no installed plugin: \['model:sirens'\]"):
        gen.expected_files()


def test_the_configuration_reference_lists_every_run_option(expected):
    text = expected[DOCS / "reference" / "config.md"]
    for name in ("split.spatial_step", "capture.gate.bins", "reconstruction.n_depths",
                 "output.keep", "scene.noise.photons", "limits.allow_large"):
        assert f"| `{name}` |" in text
    assert "| `model` |" not in text     # a plugin group: its plugin's page lists its options
