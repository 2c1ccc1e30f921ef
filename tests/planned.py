"""Plans of runs for tests: a configuration composed as the command line composes it and
made into its plan (its memory estimate included) without running it."""

from __future__ import annotations

from collections.abc import Sequence

from nlosfw.pipeline import RunPlan, make_plan
from nlosfw.plugins import PluginHost, load_plugins

#: A tiny scene (16 x 16 wall, 512 bins), 21 frequencies, 4 depth planes, interp.
TINY = ("scene=tiny", "transform.n_frequencies=21", "reconstruction.n_depths=4",
        "model=interp")


def planned(overrides: Sequence[str], host: PluginHost | None = None) -> RunPlan:
    """The plan of the run ``overrides`` describe (``limits.allow_large=true``: its memory is
    estimated, not checked; the tests check it against the memory they choose)."""
    from tests.pipeline.test_pipeline import compose

    host = load_plugins() if host is None else host
    return make_plan(compose([*overrides, "limits.allow_large=true"], host), host)
