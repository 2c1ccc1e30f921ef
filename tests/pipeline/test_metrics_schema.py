"""metrics.json has one definition (nlosfw.pipeline.metrics): the JSON Schema written beside it,
the readers (report, summary, thesis comparison) and the reference page's outline
(docs/reference/metrics.md) all come from it."""

from __future__ import annotations

import copy
import hashlib
import json
import re
import shutil
from pathlib import Path

import jsonschema
import pytest

from nlosfw.cli import main
from nlosfw.common.errors import DataError
from nlosfw.pipeline.metrics import (
    SCHEMA_VERSION,
    RunMetrics,
    metrics_outline,
    metrics_schema,
)

ROOT = Path(__file__).resolve().parents[2]
QUICK = ["scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
         "transform.n_frequencies=21", "reconstruction.n_depths=4"]

#: sha256 of the schema's structure (descriptions and title left out) for each version.
#: A change to the layout of metrics.json changes the hash: bump SCHEMA_VERSION in
#: nlosfw/pipeline/metrics.py and add the new version's hash here (never edit an old one).
LAYOUTS = {1: "df68d9802d66f6c788ccb3f73598862a1b3e03e0195b95c4a5dababd971930e2",
           2: "ce78167a70994c606d7a3b3d98a98dfe2568b521dff6e36e6459c5f264f7c834",
           3: "d12b6fae65c59b8af0701ab5ee039d632e8e4ca443ef212f9a9c6a9f64066991",
           4: "2ac7c966168c6a245c856da8074390a631b91e30621f4d35ae5aa37b2565bad3",
           5: "8a557b10430447143b70ff16e69beb7561b11132ef0c0774eb4a960439886eb4",
           6: "f97056c1ab226f7f0bdb9c183d927b8d7234b7e023c544ca3d9a5f9fb44efeb9",
           7: "9b31013e44eecda3daa1c8abe3ad5ac9e92452f4fa28745a3d8ff3c88efd5e82",
           8: "11c2bda7f7f6e7592b477ed398c22ec04d36fd56c2fa5f773331ccf8bce0e9e0",
           9: "262aa4a837b1040bcd211c67fdfb498df7f1579830c72fc399f89a0b79dd1553",
           10: "e1874bb2c7d3109dd4d55bce6fc54358ae2a0f77b2ba5ccd6ca4be54848f8172"}


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A complete run of the tiny scene (with interp, raw and true reconstructed)."""
    tmp = tmp_path_factory.mktemp("metrics_run")
    run = tmp / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(tmp / "cache"))
        mp.chdir(tmp)
        assert main([*QUICK, f"hydra.run.dir={run}"]) == 0
    return run


def _validator(run: Path) -> jsonschema.Draft202012Validator:
    schema = json.loads((run / "metrics.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_a_run_writes_a_schema_its_metrics_match(finished_run):
    data = json.loads((finished_run / "metrics.json").read_text())
    _validator(finished_run).validate(data)
    assert data["schema_version"] == SCHEMA_VERSION == 10
    metrics = RunMetrics.read(finished_run / "metrics.json")
    assert metrics.to_json() == data
    assert set(metrics.field or {}) == {"interp"}
    assert metrics.image_scores("true").ssim == pytest.approx(1.0)
    assert metrics.image_scores("true").psnr is None  # identical images: inf, stored as null
    assert metrics.timings.total >= metrics.timings.fit > 0


def _set(data, path, value):
    *parents, last = path.split(".")
    for key in parents:
        data = data[key]
    data[last] = value


def _delete(data, path):
    *parents, last = path.split(".")
    for key in parents:
        data = data[key]
    del data[last]


MUTATIONS = [
    # (what is done, key path, new value or None to delete, the reader's message)
    ("missing", "field.interp.fit.steps", None, "field.interp.fit.steps: is missing"),
    ("missing", "run", None, "run: is missing"),
    ("missing", "reconstruction.sources.raw.ssim", None,
     "reconstruction.sources.raw.ssim: is missing"),
    ("wrong type", "field.interp.fit.steps", "ten",
     "field.interp.fit.steps: must be an integer, got 'ten'"),
    ("wrong type", "reconstruction.sources.interp.ssim", "high",
     "reconstruction.sources.interp.ssim: must be a number or null, got 'high'"),
    ("wrong type", "capture.cache_hit", None, "capture.cache_hit: must be true or false, got null"),
    ("wrong type", "transform.grid", [4], "transform.grid: must be an array of 2 values, got 1"),
    ("not a choice", "status", "done", "status: must be one of 'running', 'completed', "),
    ("unknown key", "capture.colour", "red", "capture.colour: unknown key; valid keys: source,"),
]


@pytest.mark.parametrize(("change", "path", "value", "message"), MUTATIONS,
                         ids=[f"{m[0]}:{m[1]}" for m in MUTATIONS])
def test_schema_and_reader_reject_a_mutated_file(finished_run, change, path, value, message):
    data = json.loads((finished_run / "metrics.json").read_text())
    mutated = copy.deepcopy(data)
    if change == "missing":
        _delete(mutated, path)
    else:
        _set(mutated, path, value)
    validator = _validator(finished_run)
    assert validator.is_valid(data)
    assert not validator.is_valid(mutated)
    with pytest.raises(DataError) as caught:
        RunMetrics.from_json(mutated, where="m.json")
    assert str(caught.value).startswith(f"m.json: {message}")
    assert "\n" not in str(caught.value)


def _sweep_with(tmp_path, finished_run, text):
    """A sweep directory: a good run (0) and a run whose metrics.json holds ``text`` (1)."""
    sweep = tmp_path / "sweep"
    shutil.copytree(finished_run, sweep / "0")
    shutil.copytree(finished_run, sweep / "1")
    (sweep / "1" / "metrics.json").unlink()
    (sweep / "1" / "metrics.json").write_text(text)
    return sweep


@pytest.mark.malformed_metrics
@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.update(schema_version=0),
     "schema_version is 0; this nlosfw reads versions 5, 6, 7, 8, 9, 10 (written by another nlosfw "
     "version"),
    (lambda d: d["field"]["interp"]["splits"].pop("all"), "field.interp.splits.all: is missing"),
    (lambda d: d["timings"].update(total="slow"), "timings.total: must be a number, got 'slow'"),
    (None, "unreadable ("),
])
def test_report_names_the_file_and_the_problem(tmp_path, capsys, finished_run, edit, message):
    data = json.loads((finished_run / "metrics.json").read_text())
    if edit is None:
        text = '{"schema_version": 6, "status": '   # cut off mid-write
    else:
        edit(data)
        text = json.dumps(data)
    sweep = _sweep_with(tmp_path, finished_run, text)
    assert main(["report", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {sweep / '1' / 'metrics.json'}: {message}"), err
    assert err.count("\n") == 1
    assert not (sweep / "report").exists()


def test_a_version_5_file_still_reads(tmp_path, finished_run):
    """Version 6 only added optional keys (count splitting): a version-5 metrics.json (one
    without them) reads, as this version, with the same values."""
    data = json.loads((finished_run / "metrics.json").read_text())
    assert "count_splitting" not in data["capture"]
    assert "heldout_measurement" not in data["field"]["interp"]["splits"]
    old = tmp_path / "metrics_v5.json"
    old.write_text(json.dumps({**data, "schema_version": 5}))
    metrics = RunMetrics.read(old)
    assert metrics.schema_version == SCHEMA_VERSION
    assert metrics.to_json() == data
    assert metrics.field_entry("interp").splits.heldout_measurement is None


def test_a_version_8_file_reads_its_count_splitting_under_the_new_key(tmp_path, finished_run):
    """Version 9 renamed ``capture.thinning`` to ``capture.count_splitting``: a version-8
    file with the old key reads as this version, the section under its new name."""
    data = json.loads((finished_run / "metrics.json").read_text())
    halves = {"seed": 3, "count_scale": 1.0, "counts_a": 10, "counts_b": 12}
    old = tmp_path / "metrics_v8.json"
    old.write_text(json.dumps({**data, "schema_version": 8,
                               "capture": {**data["capture"], "thinning": halves}}))
    metrics = RunMetrics.read(old)
    assert metrics.schema_version == SCHEMA_VERSION
    assert metrics.capture is not None and metrics.capture.count_splitting is not None
    assert metrics.capture.count_splitting.seed == 3
    assert metrics.to_json() == {**data, "capture": {**data["capture"],
                                                     "count_splitting": halves}}
    current = tmp_path / "metrics_v9.json"    # the old name in a current file is refused
    current.write_text(json.dumps({**data, "capture": {**data["capture"], "thinning": halves}}))
    with pytest.raises(DataError, match="thinning"):
        RunMetrics.read(current)


def test_report_reads_runs_through_the_typed_metrics(tmp_path, finished_run):
    sweep = tmp_path / "sweep"
    shutil.copytree(finished_run, sweep / "a")
    assert main(["report", str(sweep)]) == 0
    header, row = (sweep / "report" / "report.csv").read_text().splitlines()
    cells = dict(zip(header.split(","), row.split(","), strict=True))
    metrics = json.loads((finished_run / "metrics.json").read_text())
    interp = metrics["field"]["interp"]
    assert cells["run"] == "a" and cells["status"] == "completed" and cells["scene"] == "tiny"
    assert cells["model"] == "interp" and cells["imager"] == "fft"
    assert float(cells["interp_heldout_pixels_nmse_db"]) == pytest.approx(
        interp["splits"]["heldout_pixels"]["nmse_db"], rel=1e-3)
    assert float(cells["interp_all_nmse_db"]) == pytest.approx(
        interp["splits"]["all"]["nmse_db"], rel=1e-3)
    assert float(cells["raw_ssim"]) == pytest.approx(
        metrics["reconstruction"]["sources"]["raw"]["ssim"], rel=1e-3)
    assert float(cells["total_seconds"]) == pytest.approx(metrics["timings"]["total"], rel=1e-3)
    assert cells["n_parameters"] == "" and cells["model_ssim"] == ""  # no model: interp only


def _layout(schema):
    """The schema without its prose (descriptions, title): what a reader depends on."""
    if isinstance(schema, dict):
        return {k: _layout(v) for k, v in schema.items() if k not in ("description", "title")}
    if isinstance(schema, list):
        return [_layout(v) for v in schema]
    return schema


def test_every_layout_change_bumps_the_schema_version():
    text = json.dumps(_layout(metrics_schema()), sort_keys=True)
    digest = hashlib.sha256(text.encode()).hexdigest()
    assert SCHEMA_VERSION in LAYOUTS, (
        f"add schema version {SCHEMA_VERSION} to LAYOUTS in this test: {digest}")
    assert digest == LAYOUTS[SCHEMA_VERSION], (
        "the layout of metrics.json changed: bump SCHEMA_VERSION in nlosfw/pipeline/metrics.py "
        f"and add {{{SCHEMA_VERSION + 1}: '{digest}'}} to LAYOUTS here")


def test_the_reference_page_shows_the_schema_as_defined():
    page = (ROOT / "docs" / "reference" / "metrics.md").read_text()
    block = re.search(r"<!-- metrics-outline -->\n```text\n(.*?)```\n<!-- /metrics-outline -->",
                      page, re.S)
    assert block, "docs/reference/metrics.md: the metrics outline block is missing"
    assert block.group(1) == metrics_outline(), (
        "docs/reference/metrics.md's metrics.json outline differs from "
        "nlosfw/pipeline/metrics.py; replace it with the output of: python -c 'from "
        "nlosfw.pipeline.metrics import metrics_outline as o; print(o(), end=\"\")'")
    assert f"`metrics.json` (schema version {SCHEMA_VERSION})" in page
