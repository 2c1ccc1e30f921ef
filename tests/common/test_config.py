"""Typed configs: names, types and ranges are checked with one-line errors."""

from dataclasses import dataclass, field

import pytest

from nlosfw.common.config import Choice, config_from_mapping, config_to_dict, require
from nlosfw.common.errors import ConfigError


class Mode(Choice):
    a = "a"
    b = "b"


@dataclass(frozen=True)
class Inner:
    size: tuple[float, float] = (1.0, 2.0)
    count: int = 3


@dataclass(frozen=True)
class Outer:
    name: str = "x"
    lr: float = 1e-3
    mode: Mode = Mode.a
    inner: Inner = field(default_factory=Inner)
    items: tuple[Inner, ...] = ()
    maybe: float | None = None
    flag: bool = False

    def __post_init__(self) -> None:
        require(self.lr > 0, "lr", f"must be > 0, got {self.lr}")


def test_defaults_and_coercion():
    cfg = config_from_mapping(Outer, {"lr": 1, "inner": {"size": [3, 4]}, "items": [{"count": 7}]})
    assert cfg.lr == 1.0 and isinstance(cfg.lr, float)
    assert cfg.inner == Inner(size=(3.0, 4.0), count=3)
    assert cfg.items == (Inner(count=7),)
    assert config_from_mapping(Outer, config_to_dict(cfg)) == cfg


@pytest.mark.parametrize(
    ("mapping", "expected"),
    [
        ({"lrr": 1}, "model.lrr: unknown option; valid options: flag, inner, items, lr, maybe, "
                     "mode, name"),
        ({"lr": "fast"}, "model.lr: must be a number, got 'fast' (str)"),
        ({"lr": -1.0}, "model.lr: must be > 0, got -1.0"),
        ({"mode": "c"}, "model.mode: must be one of 'a', 'b', got 'c'"),
        ({"inner": {"size": [1, 2, 3]}}, "model.inner.size: must be a list of 2 values, got 3 "
                                         "values"),
        ({"items": [{"count": 1.5}]}, "model.items[0].count: must be an integer, got 1.5 (float)"),
        ({"flag": "yes"}, "model.flag: must be true or false, got 'yes' (str)"),
        ({"lr": float("nan")}, "model.lr: must be a number, got NaN"),
    ],
)
def test_errors_name_the_option(mapping, expected):
    with pytest.raises(ConfigError) as info:
        config_from_mapping(Outer, mapping, "model")
    assert str(info.value) == expected


def test_integral_float_becomes_int_and_none_allowed():
    cfg = config_from_mapping(Outer, {"inner": {"count": 4.0}, "maybe": None})
    assert cfg.inner.count == 4 and isinstance(cfg.inner.count, int)
    assert config_from_mapping(Outer, {"maybe": 2}).maybe == 2.0


def test_choices_print_and_compare_as_their_values():
    assert str(Mode.b) == f"{Mode.b}" == "b" and Mode.b == "b"
    assert {"a": 1}[Mode.a] == 1
    assert config_to_dict(config_from_mapping(Outer, {"mode": "b"}))["mode"] == "b"


def test_a_node_composed_against_the_schema_is_built_without_refilling():
    """What Hydra composes is taken as checked; keys added with ``+key=value`` are not."""
    from omegaconf import OmegaConf

    from nlosfw.common.schema import schema_class

    node = OmegaConf.merge(schema_class(Outer), {"lr": 0.5, "items": [{"count": 2}]})
    assert config_from_mapping(Outer, node, "model") == Outer(lr=0.5, items=(Inner(count=2),))
    OmegaConf.update(node, "inner.colour", "red", force_add=True)    # as Hydra's +key=value
    with pytest.raises(ConfigError) as info:
        config_from_mapping(Outer, node, "model")
    assert str(info.value) == "model.inner.colour: unknown option; valid options: count, size"
    node = OmegaConf.merge(schema_class(Outer), {"lr": -2.0})
    with pytest.raises(ConfigError, match=r"^model\.lr: must be > 0, got -2\.0$"):
        config_from_mapping(Outer, node, "model")


def test_schema_twins_are_mutable_and_pickle_by_reference():
    """Hydra's launchers pickle the ConfigStore, which holds the twins."""
    import pickle

    from omegaconf import OmegaConf

    from nlosfw.common.schema import schema_class
    from nlosfw.simulate.analytic import AnalyticConfig
    from nlosfw.simulate.scene import Scene

    for twin in (schema_class(Scene), schema_class(AnalyticConfig, "analytic")):
        assert pickle.loads(pickle.dumps(twin)) is twin
    node = OmegaConf.structured(schema_class(Scene))
    node.time.bins = 7                                   # a frozen dataclass would refuse
    assert node.time.bins == 7 and not OmegaConf.is_readonly(node.time)
    assert OmegaConf.structured(schema_class(AnalyticConfig, "analytic")).name == "analytic"
