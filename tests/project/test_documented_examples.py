"""Every example the documentation shows runs as shown.

The Python block of the guide's Python API page (``docs/guide/python-api.md``) and those of
the other pages of ``docs/`` (but the developer guide's, whose blocks are templates and copies
of the example packages, checked by their own tests), the
example of :mod:`nlosfw.api`'s docstring, and every keyword example (``gate=600``) and
override list the docstrings of the public functions (``nlosfw.__all__``) give. Blocks run
as written but for their sizes (:data:`SMALLER`: fewer samples and steps, a small run), so
the test is quick; each replacement must be found, so the table follows the text. A run
an example starts is composed and checked, or (in the blocks) run on the tiny scene.
"""

from __future__ import annotations

import ast
import inspect
import itertools
import re
import shlex
import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest

import nlosfw
from nlosfw.compose.inprocess import compose_run_config
from nlosfw.image import wall_voxels
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures, layouts

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
#: The guide's page of the Python API: its block runs with :data:`SMALLER` sizes.
API_PAGE = DOCS / "guide" / "python-api.md"
#: A run of a few seconds, added to the runs the blocks start.
TINY_RUN = ('"scene.wall.resolution=[16,16]", "transform.n_frequencies=21", '
            '"reconstruction.n_depths=4", "figures.enabled=false", ')
#: Sizes replaced in the blocks (text -> text, each found exactly once in its block).
SMALLER = {
    "guide": {"samples=65536": "samples=256",
               'steps=2000)': 'steps=20)',
               '"model.steps=2000"]': '"model.steps=20", ' + TINY_RUN + ']'},
    "api": {"steps=500)": "steps=20)",
            '"scene=letter_t"])': '"scene=letter_t", ' + TINY_RUN + '])'},
}


def python_blocks(markdown: str) -> list[str]:
    """The fenced ``python`` blocks of a Markdown text."""
    return re.findall(r"^```python\n(.*?)^```", markdown, re.S | re.M)


def smaller(code: str, table: dict[str, str]) -> str:
    for old, new in table.items():
        assert code.count(old) == 1, f"the example no longer holds {old!r}: update SMALLER"
        code = code.replace(old, new)
    return code


def run_block(code: str, where: str) -> dict[str, object]:
    """Execute ``code``; remove the temporary run directory a run it starts writes."""
    namespace: dict[str, object] = {"__name__": "__example__"}
    try:
        exec(compile(code, where, "exec"), namespace)
    finally:
        out = namespace.get("out")
        if out is not None and isinstance(getattr(out, "dir", None), Path):
            shutil.rmtree(out.dir, ignore_errors=True)
    return namespace


def literal_block(doc: str) -> str:
    """The reStructuredText literal block (after ``::``) of a docstring, dedented."""
    lines = doc[doc.index("::\n") + 3:].splitlines()
    block = []
    for line in lines:
        if line.strip() and not line.startswith("    "):
            break
        block.append(line)
    return textwrap.dedent("\n".join(block)).strip() + "\n"


@pytest.fixture()
def workdir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


# ----------------------------------------------------------------------- code blocks
def test_the_guide_python_api_block_runs(workdir):
    (block,) = python_blocks(API_PAGE.read_text())
    done = run_block(smaller(block, SMALLER["guide"]), "docs/guide/python-api.md")
    assert isinstance(done["image"], nlosfw.Reconstruction)
    assert (workdir / "two_planes.hdf5").is_file()


def documented_pages() -> list[Path]:
    """The pages whose Python blocks run as written: every page of docs/ but the Python API
    page (run smaller, above) and the developer guide's."""
    return [page for page in sorted(DOCS.rglob("*.md"))
            if page != API_PAGE and "developer" not in page.relative_to(DOCS).parts]


def test_the_python_blocks_of_the_docs_run(workdir):
    """Each Python block of the user-facing pages runs (none holds one today; one added is
    run here)."""
    pages = documented_pages()
    assert DOCS / "guide" / "running.md" in pages and DOCS / "reference" / "metrics.md" in pages
    for page in pages:
        for i, block in enumerate(python_blocks(page.read_text())):
            run_block(block, f"{page.relative_to(ROOT)}, block {i + 1}")


def test_the_api_module_example_runs(workdir):
    block = literal_block(inspect.getdoc(nlosfw.api) or "")
    done = run_block(smaller(block, SMALLER["api"]), "nlosfw.api's docstring")
    assert isinstance(done["image"], nlosfw.Reconstruction)
    assert done["out"].metrics.status == "completed"


# -------------------------------------------------------- examples in the docstrings
def _public_functions() -> dict[str, object]:
    return {name: getattr(nlosfw, name) for name in nlosfw.__all__
            if inspect.isfunction(getattr(nlosfw, name))}


def _spans(function: object) -> list[str]:
    return [" ".join(s.split()) for s in re.findall(r"``(.+?)``", inspect.getdoc(function)
                                                   or "", re.S)]


def keyword_examples() -> list[tuple[str, str, object]]:
    """(function, keyword, value) of every ``keyword=value`` span of the public functions'
    docstrings whose value is a Python literal."""
    found = []
    for name, function in _public_functions().items():
        for span in _spans(function):
            match = re.fullmatch(r"(\w+)=(.+)", span)
            if match is None:
                continue
            try:
                value = ast.literal_eval(match.group(2))
            except (ValueError, SyntaxError):
                continue
            found.append((name, match.group(1), value))
    return found


@pytest.fixture()
def capture_files(workdir):
    """A capture of photon counts with 1024 bins (10 m of path), the tof.mat and the
    empty.hdf5 the examples name, beside it."""
    capture = fixtures.tiny_capture(bins=1024)
    rng = np.random.default_rng(0)
    counts = capture.replace(H=rng.poisson(0.05, capture.H.shape).astype(np.float32))
    path = nlosfw.write_capture(workdir / "scan.hdf5", counts)
    nlosfw.write_capture(workdir / "empty.hdf5", counts.replace(H=np.zeros_like(counts.H)))
    layouts.write_mat5(workdir / "tof.mat", {"tofgrid": np.full((8, 8), 100.0)})
    return path


def _runners(capture_path: Path) -> dict[str, object]:
    capture = fixtures.tiny_capture()
    field = nlosfw.transform_capture(capture, "fft", n_frequencies=5)
    return {
        "load_capture": lambda key, value: nlosfw.load_capture(capture_path, **{key: value}),
        "simulate_scene": lambda key, value: nlosfw.simulate_scene("tiny", "embree",
                                                                   **{key: value}),
        "transform_capture": lambda key, value: nlosfw.transform_capture(capture, "fft",
                                                                         **{key: value}),
        "fit_model": lambda key, value: nlosfw.fit_model(field, "siren_torch",
                                                         **{key: value}),
    }


def test_every_keyword_example_of_the_docstrings_works(capture_files):
    examples = keyword_examples()
    assert ("load_capture", "gate", 600) in examples        # the example that failed
    runners = _runners(capture_files)
    for function, key, value in examples:
        assert function in runners, f"{function}'s example {key}={value!r}: add a runner"
        try:
            result = runners[function](key, value)
        except nlosfw.NlosfwError as err:
            raise AssertionError(f"nlosfw.{function}(..., {key}={value!r}): {err}") from err
        assert result is not None


def test_the_keyword_examples_change_what_they_say(capture_files):
    loaded = nlosfw.load_capture(capture_files, gate=600)
    assert not loaded.H[:600].any() and loaded.H[600:].any()
    assert nlosfw.load_capture(capture_files, time_crop=(0, 512)).H.shape[0] == 512
    assert nlosfw.load_capture(capture_files, bin=2).H.shape[1:] == (4, 4)


def test_the_override_lists_of_the_docstrings_compose():
    """``nlosfw.run``'s examples (its docstring's and the package's) are accepted as one
    configuration; the sweep it names as refused is refused."""
    host = load_plugins()
    lists = []
    for function in (nlosfw.run, nlosfw):
        for span in _spans(function):
            calls = re.findall(r"(\[\".*?\"\])", span)
            lists.extend(ast.literal_eval(text) for text in calls)
    assert ["scene=letter_t", "model=siren_torch", "model.steps=500"] in lists
    for overrides in lists:
        config = compose_run_config(overrides, host)
        assert config["model"]["name"] in {"interp", "siren_torch"}
    with pytest.raises(nlosfw.ConfigError, match="'model=a,b' is a sweep"):
        nlosfw.run(["model=a,b"])


def test_the_imager_example_of_reconstruct_runs():
    (span,) = [s for s in _spans(nlosfw.reconstruct) if "registry.create" in s]
    field = nlosfw.transform_capture(fixtures.tiny_capture(), "fft", n_frequencies=5)
    image = eval(span, {"load_plugins": load_plugins, "field": field,
                        "voxels": wall_voxels(field, [0.5, 0.6])})
    assert isinstance(image, nlosfw.Reconstruction) and image.intensity.shape[0] == 2


# ------------------------------------------------------------ the README's Run commands
#: The command line's subcommands (``python -m nlosfw <subcommand> ...``), not runs.
SUBCOMMANDS = ("image", "report", "plugins", "cache")


def readme_run_commands() -> list[list[str]]:
    """The ``python -m nlosfw`` commands of the README's ``## Run`` block, as words."""
    text = (ROOT / "README.md").read_text()
    section = re.search(r"^## Run\n(.*?)(?=^## )", text, re.M | re.S)
    assert section, "README.md has no '## Run' section"
    block = re.search(r"```bash\n(.*?)```", section.group(1), re.S)
    assert block, "README.md's Run section has no bash block"
    commands = [shlex.split(line, comments=True) for line in block.group(1).splitlines()]
    return [words[3:] for words in commands if words[:3] == ["python", "-m", "nlosfw"]]


def test_the_readme_run_commands_compose(capture_files):
    """Each run of the README's Run block composes as one configuration (each job of its
    sweep; the capture file it names replaced by a real capture), and every other line is
    one of the command line's subcommands."""
    host = load_plugins()
    commands = readme_run_commands()
    assert [] in commands and any(c[:1] == ["-m"] for c in commands)
    composed = 0
    for words in commands:
        if words[:1] and words[0] in SUBCOMMANDS:
            continue
        sweep = words[:1] == ["-m"]
        overrides = [re.sub(r"=[\w./-]+\.mat$", f"={capture_files}", o)
                     for o in (words[1:] if sweep else words)]
        choices = [[f"{o.split('=', 1)[0]}={v}" for v in o.split("=", 1)[1].split(",")]
                   if sweep and "," in o else [o] for o in overrides]
        for job in itertools.product(*choices):
            config = compose_run_config(list(job), host)
            assert config["model"]["name"], job
            composed += 1
    assert composed >= 6     # the bare run, the capture file, the sweep's four jobs
