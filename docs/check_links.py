"""Check the external links (http and https) of the documentation: the README, CONTRIBUTING,
the CHANGELOG, every page of docs/ and the study pages.

    python docs/check_links.py [--timeout SECONDS]

It needs the network, so the test suite does not run it (``mkdocs build --strict`` checks
the internal links offline). Prints one line per link that does not answer with a success
(after redirects), naming the file and the link; exit status 1 when there is one, else 0.
A server that refuses HEAD is asked again with GET.
"""

from __future__ import annotations

import argparse
import re
import sys
import urllib.error
import urllib.request
from collections.abc import Iterable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: A Markdown link's or an angle-bracketed autolink's external target.
URL = re.compile(r"\]\((https?://[^)\s]+)\)|<(https?://[^>\s]+)>")


def documentation_files(root: Path = ROOT) -> list[Path]:
    """The Markdown files whose links are checked."""
    files = [root / name for name in ("README.md", "CONTRIBUTING.md", "CHANGELOG.md")]
    files += sorted((root / "docs").rglob("*.md")) + sorted(root.glob("studies/*/README.md"))
    return [path for path in files if path.is_file()]


def external_links(files: Iterable[Path]) -> dict[str, list[Path]]:
    """Each external link and the files that hold it."""
    found: dict[str, list[Path]] = {}
    for path in files:
        for match in URL.finditer(path.read_text(encoding="utf-8")):
            url = match.group(1) or match.group(2)
            found.setdefault(url, []).append(path)
    return found


def problem(url: str, timeout: float) -> str | None:
    """Why ``url`` does not answer with a success, or None."""
    headers = {"User-Agent": "nlosfw-docs-link-check"}
    last = ""
    for method in ("HEAD", "GET"):
        request = urllib.request.Request(url, method=method, headers=headers)
        try:
            with urllib.request.urlopen(request, timeout=timeout):
                return None
        except urllib.error.HTTPError as err:
            last = f"HTTP {err.code}"
        except (urllib.error.URLError, TimeoutError, OSError) as err:
            last = str(getattr(err, "reason", err))
    return last


def main(argv: Sequence[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timeout", type=float, default=20.0)
    args = parser.parse_args(argv)
    links = external_links(documentation_files())
    failed = 0
    for url, paths in sorted(links.items()):
        why = problem(url, args.timeout)
        if why is not None:
            failed += 1
            where = ", ".join(sorted({str(p.relative_to(ROOT)) for p in paths}))
            sys.stdout.write(f"{where}: {url}: {why}\n")
    sys.stdout.write(f"{len(links)} external links, {failed} failed\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
