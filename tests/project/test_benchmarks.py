"""The benchmarks' layout: speed and memory scripts grouped by package around one harness,
each declaring the top-level keys of the results file it writes; every committed results
file belongs to one script and holds exactly those keys (read from the scripts' source, so
the test runs none of them). No script computes or records a quality score: those are the
studies'."""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
RESULTS = BENCHMARKS / "results"
SCRIPTS = sorted(BENCHMARKS.glob("*/bench_*.py"))


def _declared(script: Path) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """(the results file's name, or a prefix ending in ``_`` for a labelled family;
    RESULT_KEYS; OPTIONAL_KEYS) as the script's module-level assignments give them."""
    name, keys, optional = "", (), ()
    for node in ast.parse(script.read_text(encoding="utf-8")).body:
        if not (isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name)):
            continue
        target = node.targets[0].id
        if target == "RESULTS" and isinstance(node.value, ast.BinOp):
            name = ast.literal_eval(node.value.right)
        elif target == "RESULTS_PREFIX":
            name = ast.literal_eval(node.value)
        elif target == "RESULT_KEYS":
            keys = ast.literal_eval(node.value)
        elif target == "OPTIONAL_KEYS":
            optional = ast.literal_eval(node.value)
    return name, keys, optional


def _owner(result: Path) -> Path | None:
    for script in SCRIPTS:
        name = _declared(script)[0]
        if result.name == name or (name.endswith("_") and result.name.startswith(name)):
            return script
    return None


def test_the_layout_is_one_harness_and_package_folders():
    assert (BENCHMARKS / "harness.py").is_file()
    loose = sorted(p.name for p in BENCHMARKS.glob("*.py"))
    assert loose == ["compare_metrics.py", "harness.py"], loose
    folders = sorted(p.name for p in BENCHMARKS.iterdir() if p.is_dir()
                     and p.name not in ("results", "__pycache__"))
    assert set(folders) <= {"capture", "transform", "model", "image", "pipeline", "simulate"}
    assert SCRIPTS, "no benchmark scripts found"


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: str(p.relative_to(BENCHMARKS)))
def test_every_script_declares_its_results_and_writes_them_through_the_harness(script):
    name, keys, _ = _declared(script)
    assert name.endswith((".json", "_")) and keys, f"{script.name}: RESULTS / RESULT_KEYS"
    source = script.read_text(encoding="utf-8")
    assert "write_results(" in source and "from harness import" in source
    assert ".write_text(json.dumps" not in source


@pytest.mark.parametrize("result", sorted(RESULTS.glob("*.json")), ids=lambda p: p.name)
def test_every_results_file_holds_its_scripts_declared_keys(result):
    script = _owner(result)
    assert script is not None, f"{result.name}: no benchmark script declares it"
    _, keys, optional = _declared(script)
    found = set(json.loads(result.read_text(encoding="utf-8")))
    assert set(keys) <= found <= set(keys) | set(optional), (
        f"{result.name}: keys {sorted(found)}; {script.name} declares {sorted(keys)} "
        f"(optional {sorted(optional)})")


def test_the_harness_refuses_results_whose_keys_differ(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import harness

    with pytest.raises(ValueError, match="RESULT_KEYS"):
        harness.write_results(tmp_path / "x.json", {"a": 1, "b": 2}, ("a",))
    assert not (tmp_path / "x.json").exists()
    written = harness.write_results(tmp_path / "x.json", {"a": 1, "b": 2}, ("a",), ("b",))
    assert json.loads(written.read_text()) == {"a": 1, "b": 2}


def test_compare_metrics_reads_an_older_file_as_the_current_schema(tmp_path):
    """A count-splitting run recorded before ``capture.thinning`` was renamed compares equal
    to the same run today; a float that changed in its last bit does not."""
    from nlosfw.pipeline import SCHEMA_VERSION

    halves = {"seed": 0, "photons": 1234.0, "halves": [617.0, 617.0]}
    after = {"schema_version": SCHEMA_VERSION, "run": {"started": "today", "seed": 3},
             "capture": {"count_splitting": halves, "bins": 64}}
    before = {**after, "schema_version": 8, "run": {"started": "yesterday", "seed": 3},
              "capture": {"thinning": halves, "bins": 64}}
    files = []
    for name, data in (("before.json", before), ("after.json", after)):
        files.append(tmp_path / name)
        files[-1].write_text(json.dumps(data))
    compare = subprocess.run([sys.executable, str(BENCHMARKS / "compare_metrics.py"),
                              *map(str, files)], capture_output=True, text=True, timeout=120)
    assert compare.returncode == 0, compare.stdout + compare.stderr
    changed = {**after, "capture": {"count_splitting": {**halves, "photons": 1234.0000000000002},
                                    "bins": 64}}
    files[1].write_text(json.dumps(changed))
    compare = subprocess.run([sys.executable, str(BENCHMARKS / "compare_metrics.py"),
                              *map(str, files)], capture_output=True, text=True, timeout=120)
    assert compare.returncode == 1
    assert "capture.count_splitting.photons: 1234.0 before, 1234.0000000000002 after" in \
        compare.stdout


#: What a benchmark may take from :mod:`nlosfw.evaluation`: the split protocol (the shape
#: of what a model is fitted to) and its size against the data, never a score.
PROTOCOL_NAMES = {"split_field", "FieldSplit", "SpatialSampling", "parameter_data_ratio"}
#: Names of written keys that hold a quality score: those belong in a study's results.json.
#: (``error`` alone is not among them: ``simulate/bench_simulators.py`` times how fast a
#: simulator reaches a given error, and ``image/bench_speed.py`` checks its fast path
#: against the direct sum it times it against.)
SCORE_KEY = re.compile(r"psnr|ssim|nmse|ncc|excess|floor_db|relative_l2|heldout|^errors$|^metrics$"
                       r"|^scores$")


def _score_uses(script: Path) -> list[str]:
    """The evaluation names ``script`` imports (splits aside) and the score-like keys it
    writes (string keys of dict displays and subscript assignments)."""
    found = []
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                "nlosfw.evaluation"):
            found += [f"imports {a.name}" for a in node.names if a.name not in PROTOCOL_NAMES]
        elif isinstance(node, ast.Import):
            found += [f"imports {a.name}" for a in node.names
                      if a.name.startswith("nlosfw.evaluation")]
        keys: list[ast.expr | None] = []
        if isinstance(node, ast.Dict):
            keys = list(node.keys)
        elif isinstance(node, ast.Assign):
            keys = [t.slice for t in node.targets if isinstance(t, ast.Subscript)]
        found += [f"writes key {k.value!r}" for k in keys
                  if isinstance(k, ast.Constant) and isinstance(k.value, str)
                  and SCORE_KEY.search(k.value)]
    return found


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: str(p.relative_to(BENCHMARKS)))
def test_no_benchmark_computes_or_records_a_quality_score(script):
    """Benchmarks measure speed and memory; a score belongs in a study (through a run's
    metrics.json), so a script neither imports a score from nlosfw.evaluation nor writes a
    key named like one."""
    assert _score_uses(script) == [], f"{script.relative_to(ROOT)}: {_score_uses(script)}"


def _keys(value: object) -> set[str]:
    if isinstance(value, dict):
        return {str(k) for k in value} | {k for v in value.values() for k in _keys(v)}
    if isinstance(value, list):
        return {k for v in value for k in _keys(v)}
    return set()


@pytest.mark.parametrize("result", sorted(RESULTS.glob("*.json")), ids=lambda p: p.name)
def test_no_committed_benchmark_result_holds_a_quality_score(result):
    scores = sorted(k for k in _keys(json.loads(result.read_text(encoding="utf-8")))
                    if SCORE_KEY.search(k))
    assert scores == [], f"{result.name}: {scores} belong in a study's results.json"
