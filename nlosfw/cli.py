"""Command line: ``python -m nlosfw [--help | plugins [NAME] | report DIR | --debug | Hydra
overrides...]``."""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from nlosfw.common.errors import USER_ERROR_EXIT_STATUS, NlosfwError


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status (2 for errors the user can fix)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if "--debug" in args:
        args = [a for a in args if a != "--debug"]
        os.environ["NLOSFW_DEBUG"] = "1"
        os.environ["HYDRA_FULL_ERROR"] = "1"
    from nlosfw.app.errors import report_user_error

    try:
        if args[:1] not in (["plugins"], ["report"]) and ("--help" in args or "-h" in args):
            from nlosfw.app.help import help_text
            from nlosfw.app.hydra_app import config_dir
            from nlosfw.plugins import load_plugins

            sys.stdout.write(help_text(load_plugins(), config_dir()) + "\n")
            return 0
        if args[:1] == ["plugins"]:
            from nlosfw.app.plugins_command import plugins_command
            from nlosfw.plugins import load_plugins

            return plugins_command(load_plugins(), args=args[1:])
        if args[:1] == ["report"]:
            from nlosfw.app.report import report_command

            return report_command(args[1:])
        from nlosfw.app.hydra_app import main as hydra_main

        return hydra_main(args)
    except NlosfwError as err:
        report_user_error(err)
        return USER_ERROR_EXIT_STATUS
