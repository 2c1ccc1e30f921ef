"""Build the Python API reference (HTML) from the docstrings with pdoc.

    python docs/build_api.py [OUTPUT_DIR]      # default: docs/api (not committed)

Documents the top-level ``nlosfw`` (the Python API for notebooks: ``nlosfw.run`` and one
function per stage), each stage package's public names (its ``__all__``), and the typed
results and metrics a run returns. Open ``OUTPUT_DIR/index.html``; nothing is fetched.
"""

from __future__ import annotations

import sys
from pathlib import Path

#: The documented modules: the public API, stage by stage.
MODULES = (
    "nlosfw",
    "nlosfw.api",
    "nlosfw.common",
    "nlosfw.capture",
    "nlosfw.simulate",
    "nlosfw.transform",
    "nlosfw.model",
    "nlosfw.model.neural",
    "nlosfw.model.physics",
    "nlosfw.model.hybrid",
    "nlosfw.image",
    "nlosfw.evaluation",
    "nlosfw.plugins",
    "nlosfw.testing",
    "nlosfw.pipeline.results",
    "nlosfw.pipeline.metrics",
)


def build(output_dir: Path) -> Path:
    """Write the reference into ``output_dir``; returns its index page."""
    import pdoc
    import pdoc.render

    from nlosfw import __version__

    pdoc.render.configure(docformat="restructuredtext", search=True,
                          footer_text=f"nlosfw {__version__}")
    pdoc.pdoc(*MODULES, output_directory=Path(output_dir))
    return Path(output_dir) / "index.html"


if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "api")
    sys.stdout.write(f"API reference: {build(out)}\n")
