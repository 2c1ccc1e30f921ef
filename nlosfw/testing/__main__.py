"""``python -m nlosfw.testing NAME [NAME ...] [--plan] [pytest options]``.

Prints the plan of each named plugin (``name`` or ``kind:name``, or a distribution's
name for every plugin it registers): the checks its
declared capabilities select and those skipped, with reasons; then, unless
``--plan``, runs them with pytest (other options, e.g. ``-x`` or ``-k``, go to
pytest). Exit status: pytest's, or 2 with one line for an unknown plugin name.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

from nlosfw.common.errors import USER_ERROR_EXIT_STATUS, NlosfwError, PluginError
from nlosfw.plugins.manager import load_plugins
from nlosfw.testing.kit import check_plan, select_specs

if TYPE_CHECKING:
    import pytest


class _Selection:
    """A pytest plugin that tells :mod:`nlosfw.testing.conformance` which plugins to check."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names = names

    def pytest_configure(self, config: pytest.Config) -> None:
        from nlosfw.testing.conformance import SELECTED

        config.stash[SELECTED] = self.names


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nlosfw.testing",
                                     description="Run nlosfw's conformance kit on plugins.")
    parser.add_argument("names", nargs="+", metavar="NAME",
                        help="plugin name (siren_torch), kind:name (imager:fft), or a "
                             "distribution (nlosfw-example-imager): all its plugins")
    parser.add_argument("--plan", action="store_true",
                        help="only print which checks apply and which are skipped, and why")
    args, pytest_args = parser.parse_known_args(argv)
    try:
        registry = load_plugins().registry
        specs = select_specs(registry, names=args.names)
        found = {n for s in specs for n in (s.name, s.qualified_name, s.distribution)}
        unknown = [n for n in args.names if n not in found]
        if unknown:
            valid = ", ".join(s.qualified_name for s in registry.specs())
            raise PluginError(f"unknown plugin {', '.join(map(repr, unknown))}; valid: {valid}")
        plans = [check_plan(spec) for spec in specs]
    except NlosfwError as err:
        sys.stderr.write(f"error: {err}\n")
        return USER_ERROR_EXIT_STATUS
    sys.stdout.write("\n".join(plan.format() for plan in plans) + "\n")
    if args.plan:
        return 0
    try:
        import pytest
    except ModuleNotFoundError:
        sys.stderr.write("error: running the conformance checks needs pytest (pip install "
                         "pytest, or pip install 'nlosfw[test]'); --plan prints the plan "
                         "without it\n")
        return USER_ERROR_EXIT_STATUS

    return int(pytest.main(["--pyargs", "nlosfw.testing.conformance", "-p", "no:cacheprovider",
                            *pytest_args], plugins=[_Selection(tuple(args.names))]))


if __name__ == "__main__":
    sys.exit(main())
