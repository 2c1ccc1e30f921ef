"""The documentation site builds with ``mkdocs build --strict``, offline, and the build fails
on a broken internal link or anchor, a page missing from the nav, or a link out of docs/ to
a file the repository does not hold (docs/hooks.py)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("mkdocs", reason="mkdocs is in the test extra: pip install '.[test]'")
pytest.importorskip("material", reason="mkdocs-material is in the test extra")

ROOT = Path(__file__).resolve().parents[2]
STUDIES = ("thesis_reproduction", "sparse_scans_simulated", "sparse_scans_measured",
           "physics_terms_measured", "classical_imagers_measured")


def build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    """``mkdocs build --strict`` of ``config`` into ``site``."""
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        capture_output=True, text=True, timeout=600, cwd=config.parent,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})


def _config() -> dict:
    class Loader(yaml.SafeLoader):
        pass

    # mkdocs.yml may use !ENV and python tags; the tests read only plain keys
    Loader.add_multi_constructor("", lambda loader, suffix, node: None)
    return yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=Loader)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    done = build(ROOT / "mkdocs.yml", out)
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout}{done.stderr}"
    return out


def test_the_site_builds_strictly_with_every_page(site):
    for name in ("guide/running", "guide/outputs", "guide/failures", "guide/captures",
                 "guide/sweeps", "guide/python-api", "reference/metrics", "reference/config",
                 "reference/capabilities", "reference/api", "architecture",
                 "developer/plugins", "developer/network", "developer/imager",
                 "developer/conformance", "plugins/model/siren_torch",
                 "plugins/capture_format/lct", "plugins/imager/lct"):
        assert (site / name / "index.html").is_file(), f"no page {name}"
    assert (site / "images" / "real_imagers.png").is_file()
    assert not list(site.rglob("*.py")) and not list(site.rglob("plugin_notes.yaml"))


def test_the_site_fetches_nothing(site):
    """No page loads a script, a style sheet or a font from another host."""
    config = _config()
    assert config["theme"]["name"] == "material" and config["theme"]["font"] is False
    assert config["plugins"] == ["search"]          # no social or privacy plugin (they fetch)
    for page in site.rglob("*.html"):
        text = page.read_text()
        found = re.findall(r"<(?:script|link|img)[^>]+(?:src|href)=\"(https?://[^\"]+)\"", text)
        assert not found, f"{page.relative_to(site)} loads {found}"


def test_every_unrecognised_link_anchor_or_page_is_an_error():
    config = _config()
    assert config["strict"] is True
    assert set(config["validation"]["links"].values()) == {"warn"}
    assert set(config["validation"]["links"]) >= {"not_found", "anchors", "unrecognized_links",
                                                  "absolute_links"}
    assert config["validation"]["nav"]["omitted_files"] == "warn"


# ------------------------------------------------------------------- what the build refuses
@pytest.fixture()
def repo(tmp_path) -> Path:
    """A copy of docs/ and mkdocs.yml beside links to the rest of the repository."""
    copy = tmp_path / "repo"
    copy.mkdir()
    shutil.copytree(ROOT / "docs", copy / "docs", ignore=shutil.ignore_patterns("api"))
    shutil.copy(ROOT / "mkdocs.yml", copy / "mkdocs.yml")
    for entry in ROOT.iterdir():
        if entry.name not in {"docs", "mkdocs.yml", "site", ".git", ".venv"}:
            (copy / entry.name).symlink_to(entry)
    return copy


def test_the_copy_of_the_site_builds(repo, tmp_path):
    """The copy the tests below break builds as it is (so each failure is the defect's)."""
    done = build(repo / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stdout + done.stderr


def _append(repo: Path, page: str, text: str) -> None:
    path = repo / "docs" / page
    path.write_text(path.read_text() + f"\n{text}\n")


@pytest.mark.parametrize(("defect", "page", "text", "message"), [
    ("a link to no page", "guide/running.md", "[x](nowhere.md)", "nowhere.md"),
    ("an anchor no heading makes", "guide/running.md", "[x](outputs.md#no-such-section)",
     "no-such-section"),
    ("an anchor of the page itself", "guide/outputs.md", "[x](#no-such-section)",
     "no-such-section"),
    ("an absolute link", "guide/running.md", "[x](/guide/outputs.md)", "/guide/outputs.md"),
    ("a repository file that does not exist", "guide/running.md",
     "[x](../../conf/no_such.yaml)", "conf/no_such.yaml"),
    ("a study that is not one", "plugins/index.md", "[x](../../studies/mine/README.md)",
     "not a study"),
])
def test_the_build_fails_on(repo, tmp_path, defect, page, text, message):
    _append(repo, page, text)
    done = build(repo / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0, f"{defect}: the build passed"
    assert message in done.stdout + done.stderr, done.stdout + done.stderr


def test_the_build_fails_on_a_page_missing_from_the_nav(repo, tmp_path):
    (repo / "docs" / "guide" / "orphan.md").write_text("# Orphan\n")
    done = build(repo / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0 and "guide/orphan.md" in done.stdout + done.stderr


def test_study_pages_are_checked_once_the_repository_has_studies(repo, tmp_path):
    """With a studies/ folder every linked study page must exist; it is then a link to the
    repository's file in the built site."""
    studies = repo / "studies"
    if studies.is_symlink():
        studies.unlink()
    for name in STUDIES[1:]:
        (studies / name).mkdir(parents=True)
        (studies / name / "README.md").write_text(f"# {name}\n")
    done = build(repo / "mkdocs.yml", tmp_path / "missing")
    assert done.returncode != 0
    assert "studies/thesis_reproduction/README.md" in done.stdout + done.stderr
    (studies / STUDIES[0]).mkdir()
    (studies / STUDIES[0] / "README.md").write_text("# thesis\n")
    done = build(repo / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stdout + done.stderr
    page = (tmp_path / "site" / "plugins" / "model" / "tanh_torch" / "index.html").read_text()
    links = re.findall(r'href="([^"]*studies/thesis_reproduction/README.md)"', page)
    assert links and all((tmp_path / "site" / "plugins" / "model" / "tanh_torch" / link)
                         .resolve() == (studies / STUDIES[0] / "README.md").resolve()
                         for link in links)
