"""The kit's entry points: which checks exist, the plan for a plugin, and pytest cases."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from nlosfw.common.config import Configurable, config_to_dict
from nlosfw.common.errors import PluginError
from nlosfw.plugins.kinds import INTERFACES, PluginKind
from nlosfw.plugins.registry import PluginSpec, Registry, import_object
from nlosfw.testing.selection import CheckPlan, PlannedCheck, plan_check

if TYPE_CHECKING:
    import pytest

Check = Callable[..., None]

#: Set to 1 where the system libraries that plugins need must be there (CI): a plugin's
#: checks then run, and fail, instead of skipping with what to install.
REQUIRE_SYSTEM = "NLOSFW_REQUIRE_SYSTEM"


def checks_for(kind: PluginKind | str) -> tuple[Check, ...]:
    """Every check of plugins of ``kind`` (common checks, then kind-specific ones), whatever
    they declare; :func:`check_plan` says which apply to one plugin."""
    from nlosfw.testing import (
        checks_capture_format,
        checks_imager,
        checks_memory,
        checks_model,
        checks_simulator,
        checks_transform,
    )
    from nlosfw.testing.checks_common import COMMON_CHECKS

    specific = {
        PluginKind.SIMULATOR: checks_simulator.SIMULATOR_CHECKS,
        PluginKind.PHASOR_TRANSFORM: checks_transform.TRANSFORM_CHECKS,
        PluginKind.FIELD_MODEL: checks_model.MODEL_CHECKS + checks_memory.MEMORY_CHECKS,
        PluginKind.IMAGER: checks_imager.IMAGER_CHECKS,
        PluginKind.CAPTURE_FORMAT: checks_capture_format.CAPTURE_FORMAT_CHECKS,
    }[PluginKind(kind)]
    return COMMON_CHECKS + tuple(specific)


def check_plan(spec: PluginSpec) -> CheckPlan:
    """The checks the kit runs on ``spec`` (per variant) and those it skips, with reasons.

    Chosen from the capabilities ``spec`` declares, never from its name or type.
    ``print(check_plan(spec).format())`` shows it. An ``expected_failures`` entry that
    names no planned check is a one-line :class:`PluginError`.
    """
    planned = tuple(p for check in checks_for(spec.kind) for p in plan_check(spec, check))
    known = {p.name for p in planned} | {p.check.__name__ for p in planned}
    unknown = sorted(set(spec.expected_failures) - known)
    if unknown:
        raise PluginError(f"{spec.label}: expected_failures names no check of the kit: "
                          f"{', '.join(unknown)}; valid: {', '.join(sorted(known))}")
    return CheckPlan(spec, planned)


def select_specs(registry: Registry | None = None, kinds: Iterable[str] | None = None,
                 names: Iterable[str] | None = None) -> list[PluginSpec]:
    """Registered plugins, optionally only some kinds or names (``name``, ``kind:name``, or
    a distribution's name for every plugin it registers)."""
    if registry is None:
        from nlosfw.plugins.manager import load_plugins

        registry = load_plugins().registry
    wanted_kinds = {PluginKind(k) for k in kinds} if kinds is not None else None
    wanted_names = set(names) if names is not None else None
    return [spec for spec in registry.specs()
            if (wanted_kinds is None or spec.kind in wanted_kinds)
            and (wanted_names is None
                 or {spec.name, spec.qualified_name, spec.distribution} & wanted_names)]


def spec_of(plugin: Configurable, name: str | None = None) -> PluginSpec:
    """A plugin instance as the kit checks it: its class is the factory, its config the
    test options, its capabilities those its class declares (``capabilities``), its kind
    the interface it implements; ``name`` defaults to the class's name."""
    cls = type(plugin)
    kind = next((PluginKind(k) for k, iface in INTERFACES.items() if isinstance(plugin, iface)),
                None)
    if kind is None:
        raise PluginError(f"{cls.__name__} implements none of the plugin interfaces "
                          f"({', '.join(i.__name__ for i in INTERFACES.values())})")
    return PluginSpec(kind=kind, name=name or cls.__name__, factory=cls,
                      distribution=cls.__module__.partition(".")[0], config=cls.config_class,
                      description=(cls.__doc__ or "").strip().partition("\n")[0],
                      test_config=config_to_dict(plugin.config))


def check_cases(registry: Registry | None = None, kinds: Iterable[str] | None = None,
                names: Iterable[str] | None = None, plugins: Iterable[Configurable] = ()
                ) -> list[tuple[PluginSpec, PlannedCheck]]:
    """Every planned (plugin, check) pair, skipped ones included (see ``skip_reason``): of
    the registered plugins, or of the plugin instances ``plugins`` when given."""
    instances = list(plugins)
    specs = ([spec_of(p) for p in instances] if instances
             else select_specs(registry, kinds, names))
    return [(spec, planned) for spec in specs for planned in check_plan(spec).checks]


def system_problem(spec: PluginSpec) -> str:
    """What the machine lacks for ``spec`` outside Python (a system library), in one line,
    from the function its ``system_check`` names ('' for nothing, or no check)."""
    try:
        return str(spec.system_check and import_object(spec.system_check)() or "")
    except Exception as err:  # the plugin's own check failing is its bug: say so
        return (f"{spec.label}: its system check {spec.system_check} failed: "
                f"{type(err).__name__}: {err}")


def pytest_params(cases: Iterable[tuple[PluginSpec, PlannedCheck]]) -> list[Any]:
    """``pytest.param``s of (spec, check) pairs: skipped ones with their reason, plugins
    with missing dependencies skipped with the pip command, those missing a system library
    (:func:`system_problem`) with what to install unless
    ``NLOSFW_REQUIRE_SYSTEM=1`` (then their checks run, and fail), expected failures
    strict."""
    import pytest

    params = []
    for spec, planned in cases:
        marks = []
        missing = spec.install_command()
        if missing:
            marks.append(pytest.mark.skip(reason=f"{spec.qualified_name} needs: {missing}"))
        elif os.environ.get(REQUIRE_SYSTEM) != "1" and (lacking := system_problem(spec)):
            marks.append(pytest.mark.skip(reason=f"{spec.qualified_name}: {lacking}"))
        if planned.skip_reason:
            marks.append(pytest.mark.skip(reason=planned.skip_reason))
        reason = (spec.expected_failures.get(planned.name)
                  or spec.expected_failures.get(planned.check.__name__))
        if reason:
            marks.append(pytest.mark.xfail(reason=reason, strict=True))
        params.append(pytest.param(spec, planned, marks=marks,
                                   id=f"{spec.qualified_name}-{planned.name}"))
    return params


def parametrize_with_checks(registry: Registry | None = None, kinds: Iterable[str] | None = None,
                            names: Iterable[str] | None = None,
                            plugins: Iterable[Configurable] = ()) -> pytest.MarkDecorator:
    """A ``pytest.mark.parametrize("spec, check", ...)`` over every planned (plugin, check)
    pair of the registered plugins, or of the plugin instances ``plugins``
    (``parametrize_with_checks(plugins=[MyModel()])``, checked with their config and the
    capabilities their class declares); checks that do not apply are reported as skipped
    with the reason."""
    import pytest

    return pytest.mark.parametrize(
        "spec, check", pytest_params(check_cases(registry, kinds, names, plugins)))
