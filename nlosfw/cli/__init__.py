"""The command line: ``python -m nlosfw`` (the Hydra app and its subcommands).

The Hydra application (:mod:`~nlosfw.cli.app`) and its pre-run checks, the subcommands
``plugins``, ``report``, ``cache`` and ``--help``, and the console: the run's
:class:`~nlosfw.cli.reporter.ConsoleReporter` (a subscriber to the run hooks), progress
bars, the log handler and one-line errors.
"""

from nlosfw.cli.commands import main

__all__ = ["main"]
