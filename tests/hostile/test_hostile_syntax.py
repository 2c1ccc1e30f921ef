"""User text is data, never syntax: a file name given to ``image``, a string in a Python
mapping or a model file's options reach the run exactly as written (no Hydra grammar, no
OmegaConf interpolation, no environment variable read), and a refused Hydra flag is
refused in every spelling argparse accepts."""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest

import nlosfw
from nlosfw.capture.hdf5 import write_capture
from nlosfw.common import yaml_safe
from nlosfw.testing import fixtures

#: The value of the environment variable the hostile names ask for.
SECRET = "hunter2-s3cr3t"
#: ``image`` at its smallest: no figures, few frequencies and planes.
SMALL = ("figures.enabled=false", "transform.n_frequencies=21", "reconstruction.n_depths=4")


def capture_file(path: Path, resolution: int = 8) -> Path:
    """A tiny capture at ``path`` whose wall has ``resolution``^2 samples (which file a
    run read shows in its metrics' capture shape)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_capture(path, fixtures.tiny_capture(resolution=resolution))


def image(tools, path: Path, run_dir: Path, *extra: str) -> dict:
    """``image PATH`` into ``run_dir``; its metrics.json (the run must complete)."""
    result = tools.run("image", str(path), f"hydra.run.dir={run_dir}", *SMALL, *extra)
    assert result.returncode == 0, result.stderr
    assert SECRET not in result.stdout + result.stderr
    return json.loads((run_dir / "metrics.json").read_text())


def assert_read_literally(run_dir: Path, metrics: dict, path: Path) -> None:
    """The run read ``path`` and recorded its name exactly, and no file of the run holds
    the secret."""
    assert metrics["capture"]["path"] == str(path)
    assert metrics["run"]["capture_file"] == str(path)
    config = yaml_safe.load((run_dir / "config.yaml").read_text(encoding="utf-8"))
    assert config["capture"]["path"] == str(path)
    leaks = [p for p in run_dir.rglob("*") if p.is_file() and SECRET.encode() in p.read_bytes()]
    assert leaks == []


@pytest.fixture()
def secret(monkeypatch):
    monkeypatch.setenv("SECRET_TOKEN", SECRET)
    monkeypatch.delenv("NOPE", raising=False)


# ------------------------------------------------------------------ file names
def test_an_environment_interpolation_in_a_file_name_is_not_resolved(workdir, tools, secret):
    path = capture_file(workdir / "scan${oc.env:SECRET_TOKEN}.hdf5")
    capture_file(workdir / f"scan{SECRET}.hdf5", resolution=6)   # what resolving would read
    metrics = image(tools, path, workdir / "run")
    assert_read_literally(workdir / "run", metrics, path)
    assert metrics["capture"]["shape"] == [256, 8, 8]


def test_an_interpolation_with_a_default_images_the_named_file_not_another(workdir, tools,
                                                                           secret):
    path = capture_file(workdir / "real${oc.env:NOPE,}.hdf5")
    capture_file(workdir / "real.hdf5", resolution=6)             # what resolving would read
    metrics = image(tools, path, workdir / "run")
    assert_read_literally(workdir / "run", metrics, path)
    assert metrics["capture"]["shape"] == [256, 8, 8]


def test_a_backslash_and_a_quote_in_a_file_name(workdir, tools, secret):
    path = capture_file(workdir / "it\\'s.hdf5")
    metrics = image(tools, path, workdir / "run")
    assert_read_literally(workdir / "run", metrics, path)


def test_a_folder_with_an_equals_sign_holds_the_capture(workdir, tools, secret):
    path = capture_file(workdir / "run=3" / "scan.hdf5")
    metrics = image(tools, path, workdir / "run")
    assert_read_literally(workdir / "run", metrics, path)


@pytest.mark.parametrize("name", [
    "it's [a], b = c %d {x: 1}.hdf5",
    'say "hi" ${oc.env:SECRET_TOKEN} $${oc.env:SECRET_TOKEN}.hdf5',
    "new\nline\ttab.hdf5",
    "\\${oc.env:SECRET_TOKEN}\\\\${oc.env:SECRET_TOKEN}\\",
    " ${hydra:runtime.cwd} ,'\\\" ",
])
def test_any_file_name_reaches_the_run_literally(workdir, tools, secret, name):
    path = capture_file(workdir / "in" / name)
    metrics = image(tools, path, workdir / "run")
    assert_read_literally(workdir / "run", metrics, path)


def test_a_sweep_of_a_hostile_file_name_resumes_with_the_same_configuration(workdir, tools,
                                                                           secret):
    """``image NAME -m``: each job and the resumed sweep's check of the jobs already there
    compose the name literally (a job whose configuration changed would be refused)."""
    path = capture_file(workdir / "a,b ${oc.env:SECRET_TOKEN} 'q'.hdf5")
    args = ("image", str(path), "-m", "imager=fft", "hydra.sweep.dir=sweep", *SMALL)
    first = tools.run(*args)
    assert first.returncode == 0, first.stderr
    again = tools.run(*args)
    assert again.returncode == 0, again.stderr
    run_dir = workdir / "sweep" / "0"
    assert_read_literally(run_dir, json.loads((run_dir / "metrics.json").read_text()), path)


def test_a_sweep_over_two_quoted_file_names_reads_each_literally(workdir, tools, secret):
    """The checks before a sweep compose each swept value again from its text; the jobs
    compose it from Hydra's; both read the names as written."""
    from nlosfw.common.text import override_value

    names = [workdir / "x ${oc.env:SECRET_TOKEN}, 'y'.hdf5", workdir / "[z]=\\.hdf5"]
    for path in names:
        capture_file(path)
    swept = ",".join(override_value(str(p)) for p in names)
    result = tools.run("-m", f"capture.path={swept}", "model=none", "hydra.sweep.dir=sweep",
                       *SMALL)
    assert result.returncode == 0, result.stderr
    for job, path in enumerate(names):
        run_dir = workdir / "sweep" / str(job)
        assert_read_literally(run_dir, json.loads((run_dir / "metrics.json").read_text()),
                              path)


def test_override_value_composes_to_the_text_itself():
    """Hydra's parser, then OmegaConf's resolution, give back any text exactly (random
    texts over the characters either gives a meaning)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    from nlosfw.common.text import override_value

    parser = OverridesParser.create()
    draw = random.Random(7)
    alphabet = "\\'\"${}:,= []()\n\t%a.-"
    texts = ["", "\\", "'", "${", "\\${x}", "a\\", "\\\\'", " x ", *(
        "".join(draw.choice(alphabet) for _ in range(draw.randint(1, 14)))
        for _ in range(600))]
    for text in texts:
        (override,) = parser.parse_overrides([f"key={override_value(text)}"])
        assert not override.is_sweep_override(), text
        stored = override.value()
        stored = getattr(stored, "text", stored)
        assert OmegaConf.to_container(OmegaConf.create({"key": stored}),
                                      resolve=True)["key"] == text, repr(text)


@pytest.mark.parametrize("study", ["sparse_scans_simulated", "sparse_scans_measured"])
def test_the_sparse_scan_studies_pass_capture_and_sweep_names_literally(tmp_path, monkeypatch,
                                                                        study):
    """A capture named as the Zaragoza dataset names its files (brackets, commas), with a
    quote and an interpolation, and a sweep folder with a comma: the command the study
    runs composes both as written."""
    import importlib.util
    import sys

    from hydra.core.override_parser.overrides_parser import OverridesParser
    from omegaconf import OmegaConf

    studies = Path(__file__).resolve().parents[2] / "studies"
    monkeypatch.syspath_prepend(str(studies))   # the studies' shared helpers
    spec = importlib.util.spec_from_file_location(f"under_test_{study}",
                                                  studies / study / "run.py")
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)
    spec.loader.exec_module(module)
    capture = tmp_path / "bunny_l[0.00,-0.50,0.00]_r[1.57] it's ${oc.env:HOME}.mat"
    sweep = tmp_path / "sweeps, 1"
    command = module.sweep_command(sweep, capture, [])
    given = {}
    for override in OverridesParser.create().parse_overrides(command[5:]):
        value = override.value()
        given[override.key_or_group] = OmegaConf.to_container(
            OmegaConf.create({"v": getattr(value, "text", value)}), resolve=True)["v"]
    assert given["capture.path"] == str(capture)
    assert given["hydra.sweep.dir"] == str(sweep)


# ------------------------------------------------------------------ Python API
def test_a_mapping_s_text_is_never_an_interpolation(secret):
    """A scene mapping given to the Python API keeps its text as written."""
    config = fixtures.tiny_scene_config()
    config["name"] = "a${oc.env:SECRET_TOKEN}b"
    capture = nlosfw.simulate_scene(config)
    assert capture.scene_info["scene"]["name"] == "a${oc.env:SECRET_TOKEN}b"


def test_a_scene_name_on_the_command_line_stays_as_the_run_composed_it(workdir, tools, secret):
    """An escaped interpolation (``\\${``) composes to ``${...}`` text; the run's own
    checks of its plain configuration must not resolve it a second time."""
    result = tools.run(*tools.QUICK, "stop_after=capture", "hydra.run.dir=run",
                       "scene.name='x\\${oc.env:SECRET_TOKEN}'")
    assert result.returncode == 0, result.stderr
    metrics = json.loads((workdir / "run" / "metrics.json").read_text())
    assert metrics["run"]["scene"] == "x${oc.env:SECRET_TOKEN}"
    assert not [p for p in (workdir / "run").rglob("*")
                if p.is_file() and SECRET.encode() in p.read_bytes()]


# ------------------------------------------------------------------ refused flags
PAYLOAD = b"cos\nsystem\n(S'touch pwned'\ntR."


@pytest.mark.parametrize("spelling", [
    ("--exp", "{payload}"),
    ("--experimental-rer={payload}",),
    ("--e={payload}",),
    ("--experimental-rerun", "{payload}"),
    ("image", "{capture}", "--experimental-re={payload}"),
    ("image", "{capture}", "--ex", "{payload}"),
])
def test_a_refused_flag_is_refused_by_any_abbreviation(workdir, tools, spelling):
    payload = workdir / "config.pickle"
    payload.write_bytes(PAYLOAD)
    capture = capture_file(workdir / "c.hdf5")
    args = [a.format(payload=payload, capture=capture) for a in spelling]
    result = tools.run(*args)
    assert result.returncode == 2
    assert tools.one_error_line(result).startswith("error: --experimental-rerun is not "
                                                   "supported: it unpickles a file")
    assert not (workdir / "pwned").exists()
    assert sorted(p.name for p in workdir.iterdir()) == ["c.hdf5", "config.pickle"]


def test_every_spelling_hydra_s_parser_takes_for_a_refused_flag_is_refused():
    """Each prefix of ``--experimental-rerun`` that Hydra's own argument parser reads as
    that flag (with its value after ``=`` or as the next argument) is refused; Hydra's
    other flags and values that merely contain the text are not."""
    from hydra._internal.utils import get_args_parser

    from nlosfw.cli.flags import refused_flag

    parser = get_args_parser()
    flag = "--experimental-rerun"
    taken = 0
    for end in range(3, len(flag) + 1):
        for args in ([flag[:end], "x"], [f"{flag[:end]}=x"]):
            known, _ = parser.parse_known_args(args)
            if known.experimental_rerun == "x":
                taken += 1
                assert refused_flag(args[0]) == flag, args
    assert taken == 2 * (len(flag) - 2)
    for harmless in ("--multirun", "-m", "--cfg=job", "--info", "-cn", "--config-name=x",
                     "capture.path=--experimental-rerun", "--", "-", "--resolve"):
        assert refused_flag(harmless) is None, harmless
