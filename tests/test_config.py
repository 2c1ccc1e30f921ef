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
