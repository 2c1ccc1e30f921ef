"""Command line: ``python -m nlosfw [--help | plugins [NAME] | report DIR | cache info|clean |
image FILE [overrides...] | --debug | Hydra overrides...]``.

Errors end with one line on stderr: exit status 2 for a mistake in the input or the
configuration, 1 for a storage failure (a full disk) or an unexpected failure (its
traceback with ``--debug``); SIGINT, SIGTERM and SIGHUP stop a run cleanly with 130,
143 and 129.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from nlosfw.common.errors import NlosfwError

IMAGE_HELP = ("Reads, preprocesses and images one capture file (capture.path=FILE model=none): "
              "writes the volume (reconstructions/true.hdf5), figures/front_true.png, "
              "depth_true.png, slices_true.png, time_profile.png and report.html. Without "
              "imager=NAME it picks the imager for the capture's geometry (lct for a "
              "confocal scan on a regular grid, else fft; the log says why). OVERRIDEs as "
              "for a run: imager=fk, reconstruction.depth_range=[0.3,0.8], ...")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the process exit status (2 for errors the user can fix)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if "--debug" in args or os.environ.get("HYDRA_FULL_ERROR") == "1":
        args = [a for a in args if a != "--debug"]
        os.environ["NLOSFW_DEBUG"] = "1"
    from nlosfw.pipeline.interrupts import as_interruption, signals_raise

    try:
        with signals_raise():
            return _dispatch(args)
    except NlosfwError as err:
        from nlosfw.cli.errors import report_user_error  # rich: only when there is an error

        report_user_error(err)
        return err.exit_status
    except SystemExit as err:  # a Hydra job's exit status (its error already reported)
        return err.code if isinstance(err.code, int) else (0 if err.code is None else 1)
    except RecursionError:  # a config or override nested past Python's limit
        from nlosfw.cli.errors import report_user_error

        report_user_error(NlosfwError("the configuration is nested too deeply"))
        return 2
    except Exception as err:  # anything else: one line (the traceback with --debug)
        from nlosfw.cli.errors import report_user_error, unexpected_error

        report_user_error(unexpected_error(err))
        return 1
    except BaseException as err:  # SIGINT, SIGTERM, SIGHUP: one line; anything else goes on
        interruption = as_interruption(err)
        if interruption is None:
            raise
        from nlosfw.cli.errors import report_interruption

        report_interruption(interruption)
        return interruption.exit_status


def _dispatch(args: list[str]) -> int:
    if args[:1] not in (["plugins"], ["report"], ["cache"], ["image"]) and (
            "--help" in args or "-h" in args):
        from nlosfw.cli.help import help_text
        from nlosfw.common.resources import config_dir
        from nlosfw.plugins import load_plugins

        sys.stdout.write(help_text(load_plugins(), config_dir()) + "\n")
        return 0
    if args[:1] == ["plugins"]:
        from nlosfw.cli.plugins_command import plugins_command
        from nlosfw.plugins import load_plugins

        return plugins_command(load_plugins(), args=args[1:])
    if args[:1] == ["report"]:
        from nlosfw.cli.report_command import report_command

        return report_command(args[1:])
    if args[:1] == ["image"]:
        from nlosfw.cli.image_command import USAGE, image_command

        if "--help" in args or "-h" in args:
            sys.stdout.write(f"usage: {USAGE}\n{IMAGE_HELP}\n")
            return 0
        return image_command(args[1:])
    if args[:1] == ["cache"]:
        from nlosfw.cli.cache_command import cache_command

        return cache_command(args[1:])
    from nlosfw.cli.app import main as hydra_main

    return hydra_main(args)
