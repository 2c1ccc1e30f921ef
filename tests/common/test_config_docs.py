"""Option documentation read from the config classes' source: types, defaults, units, text;
every built-in config documents every option, with units in the ``[unit]`` tag."""

from __future__ import annotations

import dataclasses
import enum
import re
from dataclasses import dataclass, field
from typing import get_type_hints

import pytest

from nlosfw.common.config_docs import OptionDoc, option_docs, split_unit, type_text
from nlosfw.pipeline.settings import RunSettings
from nlosfw.plugins import load_plugins
from nlosfw.simulate.scene import Scene

#: The distributions of this repository: their configs follow the documentation convention.
OUR_DISTRIBUTIONS = {"nlosfw", "nlosfw-embree", "nlosfw-mitsuba", "nlosfw-torch", "nlosfw-jax",
                     "nlosfw-example-plugin", "nlosfw-example-network"}

#: Units the built-in configs use.
UNITS = {"m", "1/m", "s", "ps", "deg", "MiB", "GB"}

#: A unit written in the text instead of the tag (the style the tag replaced).
UNTAGGED_UNIT = re.compile(r"\((?:m|s|ps|MiB|deg|cycles/m|m of path)\)"
                           r"|\bin (?:metres|seconds|picoseconds|degrees)\b")


class Mode(enum.Enum):
    fast = "fast"
    exact = "exact"


@dataclass(frozen=True)
class BaseOptions:
    seed: int = 0
    """Seed of everything random."""


@dataclass(frozen=True)
class Options(BaseOptions):
    size: float = 0.5
    """[m] Side of the patch. A second sentence
    on two lines."""
    mode: Mode = Mode.fast
    """How to compute it."""
    depths: tuple[float, ...] = (1.0, 2.0)
    limit: float | None = None
    """[s] Time budget; null: none."""
    pair: tuple[int, int] = (3, 4)
    """[MiB]No space after the tag."""
    extra: dict[str, int] = field(default_factory=dict)
    """Free-form options."""


def test_option_docs_read_type_default_unit_and_text_from_the_source():
    docs = {o.name: o for o in option_docs(Options)}
    assert list(docs) == ["seed", "size", "mode", "depths", "limit", "pair", "extra"]
    assert docs["seed"] == OptionDoc("seed", "int", 0, "", "Seed of everything random.")
    assert docs["size"] == OptionDoc("size", "float", 0.5, "m",
                                     "Side of the patch. A second sentence on two lines.")
    assert docs["size"].summary == "Side of the patch."
    assert docs["mode"] == OptionDoc("mode", "fast | exact", "fast", "", "How to compute it.")
    assert docs["depths"] == OptionDoc("depths", "list of float", [1.0, 2.0], "", "")
    assert docs["limit"] == OptionDoc("limit", "float or null", None, "s",
                                      "Time budget; null: none.")
    assert docs["pair"] == OptionDoc("pair", "[int, int]", [3, 4], "MiB",
                                     "No space after the tag.")
    assert docs["extra"] == OptionDoc("extra", "mapping", {}, "", "Free-form options.")


def test_a_subclass_docstring_overrides_its_base():
    @dataclass(frozen=True)
    class Child(Options):
        seed: int = 7
        """The child's own seed."""

    docs = {o.name: o for o in option_docs(Child)}
    assert docs["seed"] == OptionDoc("seed", "int", 7, "", "The child's own seed.")
    assert docs["size"].unit == "m"


@dataclass(frozen=True)
class Inner:
    step: float = 0.1
    """[m] Plane spacing."""


@dataclass(frozen=True)
class Outer:
    seed: int = 0
    """Seed."""
    depth: Inner = field(default_factory=Inner)
    """The planes."""


def test_a_group_of_options_is_given_as_its_options_on_request():
    assert [o.name for o in option_docs(Outer)] == ["seed", "depth"]
    flat = {o.name: o for o in option_docs(Outer, groups=True)}
    assert list(flat) == ["seed", "depth.step"]
    assert flat["depth.step"] == OptionDoc("depth.step", "float", 0.1, "m", "Plane spacing.")


@dataclass(frozen=True)
class OwnDefaults:
    depth: Inner = field(default_factory=lambda: Inner(step=0.25))
    """The planes, coarser here."""


def test_a_groups_options_show_the_defaults_its_config_gives_it():
    """A config that gives a group defaults of its own (the ensemble's volume) lists them,
    not the group class's."""
    assert {o.name: o.default for o in option_docs(OwnDefaults, groups=True)} == \
        {"depth.step": 0.25}
    from nlosfw.model.hybrid import EnsembleConfig
    found = {o.name: o.default for o in option_docs(EnsembleConfig, groups=True)}
    ours = EnsembleConfig().volume
    assert found["volume.albedo_tv"] == ours.albedo_tv > 0
    assert found["volume.prior.fit_frequencies"] == ours.prior.fit_frequencies == 64


def test_split_unit_and_type_text_edge_cases():
    assert split_unit("  [1/m]  Explicit\n   frequencies. ") == ("1/m", "Explicit frequencies.")
    assert split_unit("Inputs are scaled into [-margin, margin].") == (
        "", "Inputs are scaled into [-margin, margin].")
    assert type_text(tuple[int, ...] | None) == "list of int or null"
    assert type_text(Scene) == "group"
    with pytest.raises(TypeError):
        option_docs(int)


def _builtin_config_classes() -> dict[str, type]:
    """Every config class of this repository's plugins, and the run settings and scene
    classes with their nested groups, by a readable name."""
    host = load_plugins(env={})
    classes = {spec.qualified_name: spec.config_class() for spec in host.registry.specs()
               if spec.distribution in OUR_DISTRIBUTIONS}
    assert len({c for c in classes.values()}) >= 10, classes

    def nested(cls: type, name: str) -> None:
        classes[name] = cls
        hints = get_type_hints(cls)
        for f in dataclasses.fields(cls):
            args = getattr(hints[f.name], "__args__", ())
            for tp in (hints[f.name], *args):
                if isinstance(tp, type) and dataclasses.is_dataclass(tp):
                    nested(tp, f"{name}.{f.name}")

    nested(RunSettings, "run settings")
    nested(Scene, "scene")
    for name, cls in list(classes.items()):
        if ":" in name:                  # a plugin's config and its groups (model.prior.*)
            nested(cls, name)
    return classes


def test_every_builtin_option_is_documented_with_its_unit_in_the_tag():
    undocumented, untagged, unknown_units = [], [], []
    for name, cls in _builtin_config_classes().items():
        for option in option_docs(cls):
            where = f"{name}: {cls.__qualname__}.{option.name}"
            if not option.doc:
                undocumented.append(where)
            if UNTAGGED_UNIT.search(option.doc):
                untagged.append(f"{where}: {option.doc}")
            if option.unit and option.unit not in UNITS:
                unknown_units.append(f"{where}: [{option.unit}]")
    assert not undocumented, f"options without a docstring: {undocumented}"
    assert not untagged, f"units written in the text, not in a leading [unit] tag: {untagged}"
    assert not unknown_units, f"units outside {sorted(UNITS)}: {unknown_units}"


def test_the_physical_options_carry_their_units():
    """A sample of options whose unit is known: the tag says it."""
    units = {(o_cls, o.name): o.unit for o_cls, cls in _builtin_config_classes().items()
             for o in option_docs(cls)}
    assert units[("simulator:analytic", "patch_size")] == "m"
    assert units[("imager:fft", "chunk_mb")] == "MiB"
    assert units[("imager:rsd", "time")] == "m"
    assert units[("transform:fft", "f_max")] == "1/m"
    assert units[("model:siren_torch", "max_seconds")] == "s"
    assert units[("scene.time", "bin_width")] == "m"
    assert units[("scene.noise", "jitter_ps")] == "ps"
    assert units[("run settings.reconstruction", "depths")] == "m"
    assert units[("model:siren_torch", "lr")] == ""
