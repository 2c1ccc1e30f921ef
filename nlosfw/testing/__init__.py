"""The conformance kit: checks chosen by declared capabilities, fixtures, a pytest decorator.

Use it like scikit-learn's ``parametrize_with_checks``::

    from nlosfw.testing import parametrize_with_checks

    @parametrize_with_checks()                 # every registered plugin
    def test_conformance(spec, check):
        check(spec)

    @parametrize_with_checks(names=["my_model"])   # only yours
    def test_my_plugin(spec, check):
        check(spec)

or from a shell: ``python -m nlosfw.testing my_model`` (``--plan`` only prints the plan).

Plugins declare capabilities on their class (``capabilities = ("confocal", ...)``) or at
registration (``register(..., capabilities=[...])``, vocabulary in
:mod:`nlosfw.plugins.capabilities`); ``parametrize_with_checks(plugins=[instance])`` checks
plugin instances (:func:`spec_of`); each check declares what it
needs with :func:`requires`, and runs once per applicable variant (for example
once per capture geometry the plugin declares). Each planned (plugin, check)
pair becomes one test with id ``<kind>:<name>-<check>[<variant>]``; checks that
do not apply are skipped with the reason, and :func:`check_plan` lists them
without pytest. ``register(..., expected_failures={"check_name": "bug"})`` marks
known bugs as strict xfails. Plugins whose dependencies are missing are skipped
with the pip command that installs them.
"""

from __future__ import annotations

from nlosfw.common.deprecation import moved_names
from nlosfw.testing import fixtures
from nlosfw.testing.backends import BACKEND_CASES, assert_backend_matches_numpy
from nlosfw.testing.fixtures import (
    Agreement,
    analytic_agreement,
    heldout_error_db,
    relative_l2,
    rendered,
    scene_with,
    tiny_scene_config,
)
from nlosfw.testing.kit import (
    Check,
    check_cases,
    check_plan,
    checks_for,
    parametrize_with_checks,
    spec_of,
    system_problem,
)
from nlosfw.testing.selection import (
    DEVICE_LEGS,
    FREQUENCY_MODES,
    GEOMETRIES,
    VOXEL_LAYOUTS,
    CheckPlan,
    PlannedCheck,
    Variant,
    combine,
    requires,
    variant,
)

__all__ = [
    "DEVICE_LEGS",
    "Agreement",
    "analytic_agreement",
    "BACKEND_CASES",
    "FREQUENCY_MODES",
    "GEOMETRIES",
    "VOXEL_LAYOUTS",
    "Check",
    "CheckPlan",
    "PlannedCheck",
    "Variant",
    "assert_backend_matches_numpy",
    "check_cases",
    "check_plan",
    "checks_for",
    "combine",
    "fixtures",
    "heldout_error_db",
    "parametrize_with_checks",
    "spec_of",
    "system_problem",
    "requires",
    "relative_l2",
    "rendered",
    "scene_with",
    "tiny_scene_config",
    "variant",
]

#: Names this package exported before "engine" came to mean the run engine only.
__getattr__ = moved_names(__name__, {
    "ENGINE_CASES": "nlosfw.testing.backends:BACKEND_CASES",
    "assert_engine_matches_numpy": "nlosfw.testing.backends:assert_backend_matches_numpy"})
