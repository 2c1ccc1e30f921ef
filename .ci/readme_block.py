"""Print the bash code block of one README section, so CI runs exactly what the README says.

Usage: python3 .ci/readme_block.py SECTION [README]   (SECTION: a '## ' heading, e.g. Install)

The block is the first fenced ```bash block after the heading and before the next '## '
heading. Exit status 1 with one line when the section or its block is missing.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path


def readme_block(text: str, section: str) -> str:
    """The first ```bash block of ``## <section>`` in ``text``."""
    match = re.search(rf"^## {re.escape(section)}[ \t]*$(.*?)(?=^## |\Z)", text,
                      flags=re.MULTILINE | re.DOTALL)
    if match is None:
        raise LookupError(f"README has no section '## {section}'")
    block = re.search(r"^```bash[ \t]*\n(.*?)^```[ \t]*$", match.group(1),
                      flags=re.MULTILINE | re.DOTALL)
    if block is None:
        raise LookupError(f"README section '## {section}' has no ```bash block")
    return block.group(1)


def main(argv: list[str]) -> int:
    if len(argv) not in (1, 2):
        sys.stderr.write("usage: python3 .ci/readme_block.py SECTION [README]\n")
        return 2
    readme = Path(argv[1]) if len(argv) == 2 else Path(__file__).resolve().parents[1] / "README.md"
    try:
        sys.stdout.write(readme_block(readme.read_text(encoding="utf-8"), argv[0]))
    except LookupError as err:
        sys.stderr.write(f"error: {err}\n")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
