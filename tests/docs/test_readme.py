"""The README is a front page: at most 200 lines of at most 120 characters; the sections CI
and the tests read; a short run; what the studies found, each line a measured claim linking
its study page; and links that lead somewhere."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
STUDIES = ("thesis_reproduction", "sparse_scans_simulated", "sparse_scans_measured",
           "physics_terms_measured", "classical_imagers_measured")


def _section(text: str, title: str) -> str:
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"README.md has no section '## {title}'"
    return match.group(1)


def test_the_readme_is_a_front_page():
    lines = README.read_text().splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines (at most 200)"
    long = [(i, len(line)) for i, line in enumerate(lines, 1) if len(line) > 120]
    assert not long, f"README.md: lines over 120 characters (line, length): {long}"
    headings = [line[3:] for line in lines if line.startswith("## ")]
    for needed in ("Install", "Run", "What we found", "Tests"):
        assert needed in headings, f"README.md lost its '## {needed}' section"


def test_the_run_block_shows_the_ways_in():
    block = re.search(r"```bash\n(.*?)```", _section(README.read_text(), "Run"), re.S)
    assert block
    commands = [line.split("#")[0].strip() for line in block.group(1).splitlines()]
    assert "python -m nlosfw" in commands                                # the bare run
    assert any("capture.path=" in c for c in commands)                   # a capture file
    assert any(c.startswith("python -m nlosfw image ") for c in commands)
    assert any(c.startswith("python -m nlosfw -m ") and "," in c for c in commands)  # a sweep


def test_what_we_found_is_ten_measured_claims_at_most_each_linking_its_study():
    text = _section(README.read_text(), "What we found")
    items = re.findall(r"^- (.*?)(?=^- |\Z)", text, re.M | re.S)
    assert 1 <= len(items) <= 10, f"{len(items)} findings (at most ten)"
    for item in items:
        links = re.findall(r"\]\(([^)]+)\)", item)
        assert links, f"a finding without its study: {item!r}"
        for link in links:
            match = re.fullmatch(r"studies/(\w+)/README\.md", link)
            assert match and match.group(1) in STUDIES, f"not a study page: {link}"
        assert re.search(r"\d", item), f"a finding without a number: {item!r}"


def test_the_readme_links_lead_somewhere():
    """Every relative link names a file of the repository (a study page once the repository
    has its studies/), and every anchor a heading of the README."""
    text = README.read_text()
    anchors = {re.sub(r"[^\w\- ]", "", h.lower()).replace(" ", "-")
               for h in re.findall(r"^#+ (.+)$", text, re.M)}
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"https?://", target):
            continue
        path, _, anchor = target.partition("#")
        if not path:
            assert anchor in anchors, f"README.md: no heading for #{anchor}"
            continue
        if path.startswith("studies/") and not (ROOT / "studies").is_dir():
            continue
        assert (ROOT / path).exists(), f"README.md links to {path}, which does not exist"


def test_no_measured_result_is_left_in_the_readme_outside_what_we_found():
    """Results live on the study pages: no other section holds a number in dB or a result
    table (the sections' prose may still say 'about a minute')."""
    text = README.read_text()
    found = _section(text, "What we found")
    rest = text.replace(found, "")
    assert not re.findall(r"[−-]?\d+(\.\d+)? dB", rest)
    assert "<!-- sparsity" not in text
