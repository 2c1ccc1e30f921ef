"""The Python API given values of every wrong kind: each public function (``nlosfw.__all__``)
works, or refuses the value with a one-line :class:`~nlosfw.common.errors.ConfigError`
naming the keyword; never an AttributeError, TypeError or ValueError from deep inside.

Every parameter of every function is given each value of :data:`HOSTILE` (plugin options
too: the keywords the docstrings show, and every ``capture.*`` option of
:func:`nlosfw.load_capture`); a run is tried with the values a call cannot run with.
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import nlosfw
from nlosfw.capture.preprocess_options import Gate
from nlosfw.capture.source import CaptureSource
from nlosfw.testing import fixtures

#: Values of every kind a caller may pass by mistake.
HOSTILE: tuple[object, ...] = (5, -1, 2.5, float("nan"), float("inf"), "", "x", None, True,
                               [], {}, (1, 2), b"x", object(), np.array([1.0, 2.0]))


def _refused_or_works(call: Callable[[], object], keyword: str, value: object) -> None:
    try:
        call()
    except nlosfw.ConfigError as err:
        assert re.search(rf"(^|\.|\b){re.escape(keyword)}(\b|\.|\[|$)", err.option), \
            f"{keyword}={value!r}: the error names {err.option!r}: {err}"
        assert "\n" not in str(err)
    except Exception as err:   # any other error is the defect tested for
        raise AssertionError(f"{keyword}={value!r} raised {type(err).__name__}: {err}") from err


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    folder = tmp_path_factory.mktemp("api")
    capture = fixtures.tiny_capture(bins=1024)          # 0.01 m bins: 10.24 m of path
    field = nlosfw.transform_capture(capture, "fft", n_frequencies=5)
    ones = capture.replace(H=np.ones_like(capture.H))    # a gate shows in every bin
    split = nlosfw.split_field(field)
    model = nlosfw.fit_model(split.train_field, "interp")
    return {"folder": folder, "capture": capture, "path": nlosfw.write_capture(
        folder / "c.hdf5", capture), "ones": nlosfw.write_capture(folder / "ones.hdf5", ones),
        "field": field, "split": split, "model": model}


def _calls(data: dict[str, object], folder: Path) -> dict[str, tuple[Callable, dict]]:
    """Each public function and valid keyword arguments for it (cheap ones)."""
    field = data["field"]
    return {
        "simulate_scene": (nlosfw.simulate_scene, {"scene": "tiny", "simulator": "analytic"}),
        "load_capture": (nlosfw.load_capture, {"path": data["path"], "format": None}),
        "read_capture": (nlosfw.read_capture, {"path": data["path"]}),
        "write_capture": (nlosfw.write_capture, {
            "path": folder / "out.hdf5", "capture": data["capture"], "compression": 0,
            "overwrite": True, "nlosfw_attributes": True}),
        "transform_capture": (nlosfw.transform_capture, {
            "capture": data["capture"], "transform": "fft", "n_frequencies": 5}),
        "split_field": (nlosfw.split_field, {"field": field, "spatial_step": 2,
                                             "spectral": "interleaved",
                                             "spectral_fraction": 0.1}),
        "fit_model": (nlosfw.fit_model, {"field": data["split"].train_field,
                                         "model": "interp"}),
        "predict_field": (nlosfw.predict_field, {"model": data["model"], "like": field}),
        "field_metrics": (nlosfw.field_metrics, {"true_field": field, "predicted_field": field,
                                                 "split": data["split"]}),
        "depth_span": (nlosfw.depth_span, {"capture": data["capture"]}),
        "reconstruct": (nlosfw.reconstruct, {"field": field, "depths": [0.5, 0.6],
                                             "imager": "fft", "grid": None}),
    }


def test_require_raises_the_config_error_it_is_given():
    nlosfw.require(True, "model.lr", "must be > 0")
    with pytest.raises(nlosfw.ConfigError) as caught:
        nlosfw.require(False, "model.lr", "must be > 0")
    assert (caught.value.option, str(caught.value)) == ("model.lr", "model.lr: must be > 0")


#: Plugin options the docstrings show, tried with hostile values too: function -> (the
#: valid keywords the call needs, the option).
PLUGIN_OPTIONS = {
    "simulate_scene": ({"simulator": "embree"}, "samples"),
    "transform_capture": ({}, "n_frequencies"),
    "fit_model": ({"model": "siren_torch", "steps": 2}, "steps"),
}


def test_every_parameter_of_every_public_function_is_checked(data, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    calls = _calls(data, tmp_path)
    public = {name for name in nlosfw.__all__ if inspect.isfunction(getattr(nlosfw, name))}
    # run: below; require raises the ConfigError it is asked to, for the option it is given
    assert public - {"run", "require"} == set(calls), "a public function without its check"
    for name, (function, valid) in calls.items():
        params = [p for p, spec in inspect.signature(function).parameters.items()
                  if spec.kind is not inspect.Parameter.VAR_KEYWORD]
        assert set(params) <= set(valid), f"{name}: parameters {params} not all tried"
        function(**valid)                                       # the valid call works
        for keyword in params:
            for value in HOSTILE:
                if keyword == "path" and isinstance(value, str) and value:
                    continue                                    # a path (files: elsewhere)
                _refused_or_works(lambda f=function, a=valid, k=keyword, v=value:
                                  f(**{**a, k: v}), keyword, value)


@pytest.mark.parametrize("name", sorted(PLUGIN_OPTIONS))
def test_the_plugin_options_the_docstrings_show_are_checked(data, tmp_path, name):
    function, valid = _calls(data, tmp_path)[name]
    extra, option = PLUGIN_OPTIONS[name]
    for value in HOSTILE:
        _refused_or_works(lambda v=value: function(**{**valid, **extra, option: v}), option,
                          value)


@pytest.mark.parametrize("option", sorted(f.name for f in __import__("dataclasses").fields(
    CaptureSource) if f.name not in ("path", "format")))
def test_every_preprocessing_option_of_load_capture_is_checked(data, option):
    for value in HOSTILE:
        _refused_or_works(lambda v=value: nlosfw.load_capture(data["path"], **{option: v}),
                          option, value)


def test_load_capture_gate_600_works_in_every_form(data):
    """The named example: ``load_capture(path, gate=600)``, its own docstring's example,
    raised AttributeError for every gate value."""
    for gate in (600, 600.0, {"bins": 600}, Gate(bins=600), np.int64(600)):
        loaded = nlosfw.load_capture(data["ones"], gate=gate)
        assert not loaded.H[:600].any() and loaded.H[600:].all(), gate
    metres = nlosfw.load_capture(data["ones"], gate={"metres": 6.0})     # 0.01 m bins
    assert not metres.H[:600].any() and metres.H[600:].all()
    with pytest.raises(nlosfw.ConfigError, match=r"^capture\.gate\.bins: must be >= 0"):
        nlosfw.load_capture(data["path"], gate=-5)


def test_load_capture_tofgrid_5_is_a_config_error(data):
    """The named example: ``tofgrid=5`` raised a TypeError."""
    with pytest.raises(nlosfw.ConfigError) as caught:
        nlosfw.load_capture(data["path"], tofgrid=5)
    assert str(caught.value) == ("capture.tofgrid: expected a path (str or pathlib.Path), "
                                 "got 5 (int)")


def test_time_crop_and_a_path_object_work(data, tmp_path):
    assert nlosfw.load_capture(data["path"], time_crop=(100, 300)).H.shape[0] == 200
    assert nlosfw.load_capture(data["path"], time_crop=[100, 300]).H.shape[0] == 200
    with pytest.raises(nlosfw.ConfigError, match=r"^capture\.background: file not found"):
        nlosfw.load_capture(data["path"], background=tmp_path / "missing.hdf5")
    assert nlosfw.load_capture(data["path"], tofgrid="").H.shape[0] == 1024   # '': none


def test_an_unknown_plugin_name_is_a_config_error_naming_the_keyword(data):
    with pytest.raises(nlosfw.ConfigError, match=r"^imager: unknown imager plugin 'nope'; "
                                                 r"valid: .*fft"):
        nlosfw.reconstruct(data["field"], [0.5], "nope")
    with pytest.raises(nlosfw.ConfigError, match=r"^simulator: unknown simulator plugin"):
        nlosfw.simulate_scene("tiny", "nope")


#: The values a run is tried with: each refused before anything is written.
RUN_HOSTILE = {
    "overrides": (5, None, "model=interp", [5], [None], ["model=interp", b"x"], object()),
    "output_dir": (5, b"x", [], object(), ""),
    "config_name": (5, None, "", "nope", ["config"], "../config"),
}


@pytest.mark.parametrize("keyword", sorted(RUN_HOSTILE))
def test_run_refuses_what_it_cannot_run_with(tmp_path, monkeypatch, keyword):
    monkeypatch.chdir(tmp_path)
    valid = {"overrides": ["scene=tiny", "model=interp", "stop_after=capture"],
             "output_dir": tmp_path / "run", "config_name": "config"}
    for value in RUN_HOSTILE[keyword]:
        with pytest.raises(nlosfw.ConfigError) as caught:
            nlosfw.run(**{**valid, keyword: value})
        assert caught.value.option.startswith(keyword), (value, caught.value)
    assert not (tmp_path / "run").exists() and not (tmp_path / "outputs").exists()
