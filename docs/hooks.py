"""MkDocs hook: links from a page to files of the repository outside ``docs/``.

The pages link to the repository's other files (``studies/<name>/README.md``,
``conf/config.yaml``, ``CHANGELOG.md``) by the relative path that works on GitHub. MkDocs
would call such a link "not found" (it leaves the docs folder), and ``--strict`` would fail
on it. This hook checks each one itself and makes it a link to the repository:

- the target must exist in the repository, else the build fails naming the page and the
  link; a study page (``studies/<name>/...``) must be one of :data:`STUDIES`, and while
  the repository has no ``studies/`` folder at all its existence is not checked;
- the built link goes to ``repo_url``'s ``blob/main/<path>`` when ``mkdocs.yml`` sets
  ``repo_url``, else to the file in the checkout beside the built site (``site/``).

Links inside ``docs/`` are left to MkDocs' own validation (``validation:`` in mkdocs.yml).
Why not a ``docs/studies`` symlink: the study folders are code, results and figures read on
GitHub, whose pages link out of the site (``run.py``, ``benchmarks/``); and MkDocs cannot relax
``validation.links.not_found`` for one prefix only.
"""

from __future__ import annotations

import logging
import os
import posixpath
import re
from pathlib import Path
from typing import Any

from mkdocs.exceptions import PluginError

log = logging.getLogger("mkdocs.hooks.nlosfw")

#: The study folders (each page is ``studies/<name>/README.md``).
STUDIES = ("thesis_reproduction", "sparse_scans_simulated", "sparse_scans_measured",
           "physics_terms_measured", "classical_imagers_measured")
#: The scheme marking a repository link between the Markdown and the HTML stage (MkDocs
#: leaves a URL with a scheme alone).
SCHEME = "nlosfw-repo:"
LINK = re.compile(r"(\]\()([^)\s]+)(\))")
HREF = re.compile(r'href="' + re.escape(SCHEME) + r'([^"]*)"')


def repository_target(page_src: str, target: str, docs_dir: Path) -> str | None:
    """The repository path (posix, from its root) a relative link of page ``page_src``
    (relative to ``docs_dir``, the repository's ``docs/``) points to when it leaves
    ``docs_dir``; else None (also for a link leaving the repository)."""
    if re.match(r"^[a-zA-Z][\w+.-]*:", target) or target.startswith(("/", "#")):
        return None
    path, _, anchor = target.partition("#")
    joined = posixpath.normpath(posixpath.join(posixpath.dirname(page_src), path))
    if not joined.startswith("../"):
        return None
    # by the path's text, not its resolved target: docs/ and the repository's folders may be
    # links (a checkout assembled from several places)
    relative = posixpath.normpath(posixpath.join(docs_dir.name, joined))
    if relative.startswith("../"):
        return None
    return relative + (f"#{anchor}" if anchor else "")


def check_target(page_src: str, target: str, root: Path) -> None:
    """Fail the build when the repository file ``target`` does not exist (studies: see the
    module's docstring)."""
    path = target.partition("#")[0]
    parts = path.split("/")
    if parts[0] == "studies":
        if len(parts) < 2 or parts[1] not in STUDIES:
            raise PluginError(f"{page_src}: link to {target!r}: not a study; the studies are "
                              f"{', '.join(STUDIES)}")
        if not (root / "studies").is_dir():
            log.debug("%s: %s not checked: this checkout has no studies/", page_src, target)
            return
    if not (root / path).exists():
        raise PluginError(f"{page_src}: link to {target!r}: no such file in the repository")


def on_pre_build(config: Any) -> None:
    if not (Path(config["docs_dir"]).parent / "studies").is_dir():
        log.info("this checkout has no studies/: links to the study pages are not checked")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    docs_dir = Path(config["docs_dir"])
    src = page.file.src_uri

    def rewrite(match: re.Match[str]) -> str:
        target = repository_target(src, match.group(2), docs_dir)
        if target is None:
            return match.group(0)
        check_target(src, target, docs_dir.parent)
        return f"{match.group(1)}{SCHEME}{target}{match.group(3)}"

    return LINK.sub(rewrite, markdown)


def on_page_content(html: str, page: Any, config: Any, files: Any) -> str:
    repo_url = (config.get("repo_url") or "").rstrip("/")
    if repo_url:
        base = f"{repo_url}/blob/main/"
    else:
        # the checkout beside the built site: from the page's folder up to the site, then on
        site = Path(config["site_dir"]).resolve()
        up = os.path.relpath(Path(config["docs_dir"]).parent.resolve(), site)
        depth = page.url.count("/")   # the page's folder below the site's root
        base = "../" * depth + ("" if up == "." else up.rstrip("/") + "/")
    return HREF.sub(lambda m: f'href="{base}{m.group(1)}"', html)
