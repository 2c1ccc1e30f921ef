"""The developer guide's page (docs/developer/imager.md) shows this package's files verbatim:
the example there stays true."""

import re
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1]
PAGE = HERE.parents[1] / "docs" / "developer" / "imager.md"


@pytest.mark.parametrize("name", ["hooks.py", "backprojection.py"])
def test_the_guide_shows_the_example_file(name):
    source = (HERE / "nlosfw_example_imager" / name).read_text()
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)
    first_line = source.splitlines()[0]
    shown = [b for b in blocks if b.splitlines()[0] == first_line]
    assert shown, f"docs/developer/imager.md shows no block starting like {name}: {first_line!r}"
    assert shown[0] == source, f"docs/developer/imager.md's copy of {name} differs from the file"


def test_the_guide_shows_the_entry_point():
    toml = (HERE / "pyproject.toml").read_text()
    entry = re.search(r"\[project\.entry-points\.nlosfw\]\n[^\n]+\n", toml).group(0)
    assert f"```toml\n{entry}```" in PAGE.read_text()
