"""The Python API reference builds from the docstrings (docs/build_api.py, with pdoc)."""

import importlib.util
import re
from pathlib import Path

import pytest

BUILD = Path(__file__).resolve().parents[2] / "docs" / "build_api.py"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    pytest.importorskip("pdoc", reason="pdoc is in the test extra: pip install '.[test]'")
    spec = importlib.util.spec_from_file_location("build_api", BUILD)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path_factory.mktemp("api-reference")
    index = module.build(out)
    return out, index, module.MODULES


def test_every_documented_module_has_a_page(reference):
    out, index, modules = reference
    assert index.is_file()
    for name in modules:
        page = out.joinpath(*name.split(".")).with_suffix(".html")
        assert page.is_file(), f"no page for {name}"


def test_the_python_api_is_documented_from_its_docstrings(reference):
    out, _, _ = reference
    page = (out / "nlosfw" / "api.html").read_text()
    for name in ("run", "simulate_scene", "transform_capture", "fit_model", "predict_field",
                 "reconstruct"):
        assert re.search(rf'id="{name}"', page), f"nlosfw.api.{name} is not documented"
    assert "exactly as" in page and "python -m nlosfw OVERRIDES" in page   # run's docstring
    assert 'id="read_capture"' in (out / "nlosfw" / "capture.html").read_text()
    assert 'id="depth_span"' in (out / "nlosfw" / "image.html").read_text()
    assert not re.search(r"<(script|link)[^>]+(src|href)=\"https?://", page)   # nothing fetched
