"""Where nlosfw's Hydra configs are: the one lookup every module that reads them uses.

``conf/`` is installed as the package ``nlosfw.conf``. Run from a clone's root (``python
-m nlosfw``, ``python -m pytest``), the checkout's ``nlosfw/`` shadows the installed
package and has no ``nlosfw/conf``; the configs are then the checkout's ``conf/``, beside
the package.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path

from nlosfw.common.errors import PluginError

#: The package ``conf/`` is installed as.
CONFIG_PACKAGE = "nlosfw.conf"


@cache
def config_dir() -> Path:
    """The directory of ``config.yaml``: the installed ``nlosfw.conf`` package, else the
    ``conf/`` beside the imported ``nlosfw`` package (a checkout); a one-line error when
    neither exists."""
    try:
        installed = Path(str(resources.files(CONFIG_PACKAGE)))
        if (installed / "config.yaml").is_file():
            return installed
    except (ModuleNotFoundError, TypeError):
        pass
    checkout = Path(__file__).resolve().parents[2] / "conf"
    if (checkout / "config.yaml").is_file():
        return checkout
    raise PluginError(f"cannot find nlosfw's Hydra configs (package {CONFIG_PACKAGE}, or "
                      f"{checkout} beside a checkout); reinstall nlosfw with: pip install .")
