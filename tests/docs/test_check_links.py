"""docs/check_links.py finds the documentation's external links (checking them needs the
network: the suite only checks what it finds, and a refused connection is reported)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _module():
    spec = importlib.util.spec_from_file_location("nlosfw_docs_check_links",
                                                  ROOT / "docs" / "check_links.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_the_external_links_of_every_page_are_found(tmp_path):
    check = _module()
    files = check.documentation_files()
    assert ROOT / "README.md" in files and ROOT / "docs" / "guide" / "captures.md" in files
    links = check.external_links(files)
    assert ROOT / "README.md" in links["https://pluggy.readthedocs.io"]
    assert "https://graphics.unizar.es/nlos_dataset.html" in links        # an <autolink>
    page = tmp_path / "page.md"
    page.write_text("[a](https://a.example/x) <http://b.example> [c](../c.md) [d](#d)\n")
    assert check.external_links([page]) == {"https://a.example/x": [page],
                                            "http://b.example": [page]}


def test_a_link_that_does_not_answer_is_reported():
    assert _module().problem("http://127.0.0.1:9/", timeout=5)    # the discard port: refused
