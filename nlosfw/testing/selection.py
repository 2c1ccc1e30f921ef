"""How the kit picks checks from declared capabilities: requirements, variants, plans.

A check declares what it needs with :func:`requires`::

    @requires(Capability.OCCLUSION, each=GEOMETRIES)
    def check_occlusion(spec, confocal): ...

The check runs only for plugins that declare every capability named, and once
per *variant* of ``each`` whose capabilities the plugin declares (here: once per
capture geometry), receiving the variant's options as keyword arguments. With
``any_of`` it runs once, in the first variant the plugin declares. A variant
table may also map plugin kinds to variants (for checks common to every kind).
Whatever does not apply is planned as skipped, with the reason.
"""

from __future__ import annotations

import itertools
import unittest
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from nlosfw.common.config import Scalar
from nlosfw.plugins.capabilities import Capability, format_capabilities
from nlosfw.plugins.registry import PluginSpec

C = Capability
F = TypeVar("F", bound=Callable[..., None])


@dataclass(frozen=True)
class Variant:
    """One way to run a check: a name (for its id), the capabilities it needs, and the
    keyword arguments it passes to the check."""

    name: str
    needs: frozenset[Capability] = frozenset()
    options: Mapping[str, Scalar] = field(default_factory=dict)


def variant(name: str, needs: Iterable[Capability] = (), **options: Scalar) -> Variant:
    """A :class:`Variant` named ``name`` needing ``needs`` and passing ``options``."""
    return Variant(name, frozenset(needs), dict(options))


def combine(*axes: Sequence[Variant]) -> tuple[Variant, ...]:
    """Every combination of one variant per axis: names joined by ``+`` (empty names
    dropped), needs and options merged."""
    out = []
    for parts in itertools.product(*axes):
        name = "+".join(p.name for p in parts if p.name)
        needs = frozenset().union(*(p.needs for p in parts))
        options: dict[str, Scalar] = {}
        for p in parts:
            options.update(p.options)
        out.append(Variant(name, needs, options))
    return tuple(out)


#: The two capture geometries (option ``confocal``).
GEOMETRIES = (variant("single_spot", [C.SINGLE_SPOT], confocal=False),
              variant("confocal", [C.CONFOCAL], confocal=True))
#: Without and with the device legs in a simulated time axis (option ``legs``).
DEVICE_LEGS = (variant("", legs=False), variant("device_legs", [C.DEVICE_LEGS], legs=True))
#: Field models fitted on many frequencies or on one (option ``single``).
FREQUENCY_MODES = (variant("multi_frequency", [C.MULTI_FREQUENCY], single=False),
                   variant("single_frequency", [C.SINGLE_FREQUENCY], single=True))
#: Voxels as planes on the wall's grid or as a plain list (option ``plane``).
VOXEL_LAYOUTS = (variant("plane_voxels", [C.PLANE_VOXELS], plane=True),
                 variant("point_voxels", [C.POINT_VOXELS], plane=False))

VariantTable = Sequence[Variant] | Mapping[str, Sequence[Variant]]


@dataclass(frozen=True)
class Requirements:
    """What a check needs: every capability of ``needs``, and the variants it runs in."""

    needs: frozenset[Capability] = frozenset()
    each: VariantTable = ()
    any_of: VariantTable = ()


def requires(*capabilities: Capability, each: VariantTable = (),
             any_of: VariantTable = ()) -> Callable[[F], F]:
    """Declare that a check needs ``capabilities`` and runs in ``each`` (every declared
    variant) or ``any_of`` (the first declared variant) of a variant table."""
    if each and any_of:
        raise ValueError("a check runs in each variant or in any one of them, not both")

    def mark(check: F) -> F:
        check.__requirements__ = Requirements(frozenset(capabilities), each,  # type: ignore
                                              any_of)
        return check

    return mark


def requirements_of(check: Callable[..., None]) -> Requirements:
    """The :class:`Requirements` declared with :func:`requires` (none: always applies)."""
    found = getattr(check, "__requirements__", None)
    return found if isinstance(found, Requirements) else Requirements()


@dataclass(frozen=True)
class PlannedCheck:
    """A check in one variant for one plugin, and why it is skipped (``''``: it runs).

    Calling it runs the check on a spec (a skipped one raises ``unittest.SkipTest``).
    """

    check: Callable[..., None]
    variant: Variant | None = None
    skip_reason: str = ""

    @property
    def name(self) -> str:
        """``check_name`` or ``check_name[variant]``."""
        base = self.check.__name__
        return f"{base}[{self.variant.name}]" if self.variant and self.variant.name else base

    @property
    def applies(self) -> bool:
        return not self.skip_reason

    def __call__(self, spec: PluginSpec) -> None:
        if self.skip_reason:
            raise unittest.SkipTest(self.skip_reason)
        self.check(spec, **(dict(self.variant.options) if self.variant else {}))


def _variants(table: VariantTable, kind: str) -> tuple[Variant, ...]:
    if isinstance(table, Mapping):
        return tuple(table.get(kind, ()))
    return tuple(table)


def _missing_reason(spec: PluginSpec, missing: Iterable[Capability]) -> str:
    names = sorted(c.value for c in missing)
    noun = "capability" if len(names) == 1 else "capabilities"
    return (f"needs {noun} {' and '.join(names)}, which {spec.qualified_name} does not "
            "declare")


def plan_check(spec: PluginSpec, check: Callable[..., None]) -> list[PlannedCheck]:
    """The planned runs of one check for ``spec``: one per applicable variant, and the
    skipped ones with their reasons."""
    declared = spec.capabilities
    req = requirements_of(check)
    kind = spec.kind.value
    if not req.needs <= declared:
        return [PlannedCheck(check, None, _missing_reason(spec, req.needs - declared))]
    each, any_of = _variants(req.each, kind), _variants(req.any_of, kind)
    if each:
        return [PlannedCheck(check, v, "" if v.needs <= declared
                             else _missing_reason(spec, v.needs - declared)) for v in each]
    if any_of:
        first = next((v for v in any_of if v.needs <= declared), None)
        if first is not None:
            return [PlannedCheck(check, first)]
        options = " or ".join("+".join(sorted(c.value for c in v.needs)) for v in any_of)
        return [PlannedCheck(check, None, f"needs capability {options}, which "
                             f"{spec.qualified_name} declares none of")]
    return [PlannedCheck(check)]


@dataclass(frozen=True)
class CheckPlan:
    """Which checks the kit runs on one plugin, and which it skips and why."""

    spec: PluginSpec
    checks: tuple[PlannedCheck, ...]

    @property
    def applied(self) -> tuple[PlannedCheck, ...]:
        return tuple(c for c in self.checks if c.applies)

    @property
    def skipped(self) -> tuple[PlannedCheck, ...]:
        return tuple(c for c in self.checks if not c.applies)

    def format(self) -> str:
        """The plan as text: the capabilities, then one line per planned check."""
        spec = self.spec
        origin = " (declares none: the kind's defaults)" \
            if spec.capabilities_origin == "defaults" else ""
        lines = [f"{spec.qualified_name} from {spec.distribution}",
                 f"  capabilities: {format_capabilities(spec.capabilities)}{origin}"]
        for planned in self.checks:
            if planned.applies:
                xfail = spec.expected_failures.get(planned.name) \
                    or spec.expected_failures.get(planned.check.__name__)
                note = f"  (expected to fail: {xfail})" if xfail else ""
                lines.append(f"  run   {planned.name}{note}")
            else:
                lines.append(f"  skip  {planned.name}: {planned.skip_reason}")
        lines.append(f"  {len(self.applied)} to run, {len(self.skipped)} skipped")
        return "\n".join(lines)
