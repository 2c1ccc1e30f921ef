"""The conformance kit: checks every plugin must pass, fixtures, and a pytest decorator.

Use it like scikit-learn's ``parametrize_with_checks``::

    from nlosfw.testing import parametrize_with_checks

    @parametrize_with_checks()                 # every registered plugin
    def test_conformance(spec, check):
        check(spec)

    @parametrize_with_checks(names=["my_model"])   # only yours
    def test_my_plugin(spec, check):
        check(spec)

Each (plugin, check) pair becomes one test with id ``<kind>:<name>-<check>``. A
plugin lists checks it is known to fail in ``register(..., expected_failures=
{"check_name": "reason"})``; they run as strict xfails. Plugins whose
dependencies are missing are skipped with the pip command that installs them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from nlosfw.plugins.kinds import PluginKind
from nlosfw.plugins.registry import PluginSpec, Registry
from nlosfw.testing import fixtures
from nlosfw.testing.checks_common import COMMON_CHECKS
from nlosfw.testing.engines import ENGINE_CASES, assert_engine_matches_numpy
from nlosfw.testing.fixtures import (
    Agreement,
    analytic_agreement,
    relative_l2,
    rendered,
    scene_with,
    tiny_scene_config,
)

Check = Callable[[PluginSpec], None]


def checks_for(kind: PluginKind | str) -> tuple[Check, ...]:
    """Every check that applies to plugins of ``kind``: common checks, then kind-specific ones."""
    from nlosfw.testing import checks_imager, checks_model, checks_simulator, checks_transform

    specific = {
        PluginKind.SIMULATOR: checks_simulator.SIMULATOR_CHECKS,
        PluginKind.PHASOR_TRANSFORM: checks_transform.TRANSFORM_CHECKS,
        PluginKind.FIELD_MODEL: checks_model.MODEL_CHECKS,
        PluginKind.IMAGER: checks_imager.IMAGER_CHECKS,
    }[PluginKind(kind)]
    return COMMON_CHECKS + tuple(specific)


def check_cases(registry: Registry | None = None, kinds: Iterable[str] | None = None,
                names: Iterable[str] | None = None) -> list[tuple[PluginSpec, Check]]:
    """All (plugin, check) pairs, optionally restricted to some kinds or plugin names."""
    if registry is None:
        from nlosfw.plugins import load_plugins

        registry = load_plugins().registry
    wanted_kinds = {PluginKind(k) for k in kinds} if kinds is not None else None
    wanted_names = set(names) if names is not None else None
    cases = []
    for spec in registry.specs():
        if wanted_kinds is not None and spec.kind not in wanted_kinds:
            continue
        if wanted_names is not None and not ({spec.name, spec.qualified_name} & wanted_names):
            continue
        cases.extend((spec, check) for check in checks_for(spec.kind))
    return cases


def parametrize_with_checks(registry: Registry | None = None, kinds: Iterable[str] | None = None,
                            names: Iterable[str] | None = None) -> Any:
    """A ``pytest.mark.parametrize("spec, check", ...)`` over every (plugin, check) pair."""
    import pytest

    params = []
    for spec, check in check_cases(registry, kinds, names):
        marks = []
        missing = spec.install_command()
        if missing:
            marks.append(pytest.mark.skip(reason=f"{spec.qualified_name} needs: {missing}"))
        reason = spec.expected_failures.get(check.__name__)
        if reason:
            marks.append(pytest.mark.xfail(reason=reason, strict=True))
        params.append(pytest.param(spec, check, marks=marks,
                                   id=f"{spec.qualified_name}-{check.__name__}"))
    return pytest.mark.parametrize("spec, check", params)


__all__ = [
    "Agreement",
    "analytic_agreement",
    "ENGINE_CASES",
    "Check",
    "assert_engine_matches_numpy",
    "check_cases",
    "checks_for",
    "fixtures",
    "parametrize_with_checks",
    "relative_l2",
    "rendered",
    "scene_with",
    "tiny_scene_config",
]
