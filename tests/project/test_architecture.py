"""The package layout's rules: stages depend only on earlier stages, no import cycles, the
field models' families depend on each other only through the hybrids, and plugins and
examples use only the public names (``__all__``) of the stage packages and of the backend
APIs."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CORE = ROOT / "nlosfw"

#: Each package may import only packages of the same or an earlier layer.
LAYERS = {
    "nlosfw.common": 0,
    "nlosfw.capture": 1,
    "nlosfw.simulate": 2,
    "nlosfw.transform": 2,
    "nlosfw.model": 3,
    "nlosfw.image": 3,
    "nlosfw.evaluation": 4,
    "nlosfw.plugins": 4,
    "nlosfw.testing": 5,
    "nlosfw.pipeline": 5,
    "nlosfw.report": 6,
    "nlosfw.compose": 6,
    "nlosfw": 7,
    "nlosfw.cli": 8,
    "nlosfw.__main__": 8,
}

#: Imports a layer's rule allows but the architecture forbids: the library API and the
#: engine never depend on the command line or the reports (the reports are a plugin of the
#: run hooks, the console a subscriber the command line registers).
FORBIDDEN = {
    "nlosfw.api": ("nlosfw.cli", "nlosfw.report"),
    "nlosfw": ("nlosfw.cli", "nlosfw.report"),
    "nlosfw.pipeline": ("nlosfw.cli", "nlosfw.report", "nlosfw.compose"),
    "nlosfw.compose": ("nlosfw.cli", "nlosfw.report"),
}

#: Below the stage packages, the packages whose ``__all__`` is public too: the APIs the
#: backend and network plugins build on.
BACKEND_APIS = ("nlosfw.model.neural", "nlosfw.model.physics", "nlosfw.model.hybrid")

#: The field models' families: each may import the model package's own modules and the
#: families named here, nothing of the others (the hybrids build on both).
MODEL_FAMILIES = {
    "nlosfw.model.neural": (),
    "nlosfw.model.physics": (),
    "nlosfw.model.hybrid": ("nlosfw.model.neural", "nlosfw.model.physics"),
}

#: Packages that must not import these libraries at all (not even inside functions).
FORBIDDEN_LIBRARIES = {
    "nlosfw.pipeline": ("hydra", "rich", "matplotlib"),
}


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name: str) -> bool:
    base = ROOT.joinpath(*name.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def _runtime_nodes(tree: ast.AST) -> list[ast.AST]:
    """Every node of ``tree`` outside ``if TYPE_CHECKING:`` blocks (imports there are for
    annotations only and create no dependency at run time)."""
    skipped: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skipped.update(id(n) for child in node.body for n in ast.walk(child))
    return [n for n in ast.walk(tree) if id(n) not in skipped]


def _imports(path: Path) -> set[str]:
    """nlosfw modules imported anywhere in ``path`` (function-level imports included, type
    annotations' imports not)."""
    found = set()
    for node in _runtime_nodes(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] != "nlosfw":
                continue
            for alias in node.names:
                sub = f"{node.module}.{alias.name}"
                found.add(sub if _is_module(sub) else node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "nlosfw")
    return found


def _graph() -> dict[str, set[str]]:
    return {_module_name(p): _imports(p) for p in CORE.rglob("*.py")}


def _layer(module: str) -> int:
    best = max((k for k in LAYERS if module == k or module.startswith(k + ".")), key=len)
    return LAYERS[best]


def test_stages_import_only_earlier_stages():
    wrong = sorted((src, dst) for src, deps in _graph().items() for dst in deps
                   if _layer(dst) > _layer(src))
    assert not wrong, f"imports against the stage order (importer, imported): {wrong}"


def _package_of(module: str, table: dict[str, tuple[str, ...]]) -> str | None:
    matches = [k for k in table if module == k or module.startswith(k + ".")]
    return max(matches, key=len) if matches else None


def test_forbidden_imports():
    wrong = []
    for src, deps in _graph().items():
        rule = _package_of(src, FORBIDDEN)
        if rule is None or (rule == "nlosfw" and src != "nlosfw"):
            continue
        wrong += [(src, dst) for dst in deps
                  if any(dst == f or dst.startswith(f + ".") for f in FORBIDDEN[rule])]
    assert not wrong, f"imports the architecture forbids (importer, imported): {wrong}"


def test_model_families_import_only_the_families_they_build_on():
    wrong = []
    for src, deps in _graph().items():
        own = _package_of(src, {k: () for k in MODEL_FAMILIES})
        for dst in deps:
            other = _package_of(dst, {k: () for k in MODEL_FAMILIES})
            if other is None or other == own:
                continue
            if own is None:     # a module of the model package's root, or another stage
                if src.startswith("nlosfw.model.") and other != "nlosfw.model.neural":
                    wrong.append((src, dst))
            elif other not in MODEL_FAMILIES[own]:
                wrong.append((src, dst))
    assert not wrong, f"imports between model families (importer, imported): {wrong}"


def test_engine_imports_no_ui_library():
    wrong = []
    for path in CORE.rglob("*.py"):
        rule = _package_of(_module_name(path), FORBIDDEN_LIBRARIES)
        if rule is None:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
            wrong += [f"{_module_name(path)}: {n}" for n in names
                      if n.split(".")[0] in FORBIDDEN_LIBRARIES[rule]]
    assert not wrong, f"the engine imports a UI library: {wrong}"


def test_no_import_cycles():
    graph = _graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def _third_party_sources() -> list[Path]:
    """The plugins' and examples' sources, not the copies a non-editable install leaves in
    their ``build/`` folders (so both installs check the same files)."""
    found = [*ROOT.glob("plugins/*/**/*.py"), *ROOT.glob("examples/**/*.py")]
    return sorted(p for p in found if "build" not in p.relative_to(ROOT).parts)


def _script_sources() -> list[Path]:
    """The benchmarks' and the studies' scripts: they use nlosfw as its users do."""
    return sorted([*ROOT.glob("benchmarks/**/*.py"), *ROOT.glob("studies/**/*.py")])


@pytest.mark.parametrize("path", _third_party_sources() + _script_sources(),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_plugins_examples_benchmarks_and_studies_use_only_public_names(path):
    private = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            private += [a.name for a in node.names if a.name.split(".")[0] == "nlosfw"]
        if not (isinstance(node, ast.ImportFrom) and node.module
                and node.module.split(".")[0] == "nlosfw"):
            continue
        module = importlib.import_module(node.module)
        public = set(getattr(module, "__all__", ()))
        api = node.module.count(".") <= 1 or node.module in BACKEND_APIS
        for alias in node.names:
            if not api or alias.name not in public:
                private.append(f"{node.module}.{alias.name}")
    assert not private, (f"{path.relative_to(ROOT)} imports names outside the stage packages' "
                         f"and the backend APIs' __all__: {private}")
    assert _script_sources(), "no benchmark or study scripts found"


def test_every_public_name_exists():
    for package in [m for m in LAYERS if m.count(".") == 1 and m != "nlosfw.cli"
                    and m != "nlosfw.__main__"] + ["nlosfw", *BACKEND_APIS]:
        module = importlib.import_module(package)
        missing = [n for n in getattr(module, "__all__", ()) if not hasattr(module, n)]
        assert not missing, f"{package}.__all__ names what it does not define: {missing}"


def _imported_names(path: Path) -> list[str]:
    """Every module name ``path`` imports (any library, function-level imports included)."""
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names += [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
    return names


def test_only_the_evaluation_package_imports_skimage_metrics():
    """Reconstruction scores have one implementation, :mod:`nlosfw.evaluation.image_scores`:
    no other module, plugin, example, benchmark or study imports scikit-image's metrics."""
    sources = sorted([*CORE.rglob("*.py"), *_third_party_sources(), *_script_sources()])
    importers = sorted({str(path.relative_to(ROOT)) for path in sources
                        if any(n.split(".")[0] == "skimage" for n in _imported_names(path))})
    assert importers == ["nlosfw/evaluation/image_scores.py"]


def test_the_metrics_recorder_computes_nothing():
    """The recorder copies the sections the stages' results carry: it imports neither the
    protocol, nor the section builders, nor anything that computes."""
    names = _imported_names(CORE / "pipeline" / "recorder.py")
    computing = [n for n in names if n.split(".")[0] in ("numpy", "scipy", "skimage")
                 or n.startswith(("nlosfw.evaluation", "nlosfw.pipeline.measure"))]
    assert not computing, f"the metrics recorder imports {computing}"


def test_no_private_hydra_or_omegaconf_api():
    """Hydra and OmegaConf are used through their public API only (no ``hydra._internal``)."""
    sources = sorted([*CORE.rglob("*.py"), *_third_party_sources()])
    private = []
    for path in sources:
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
            private += [f"{path.relative_to(ROOT)}: {n}" for n in names
                        if n.split(".")[0] in ("hydra", "omegaconf")
                        and any(part.startswith("_") for part in n.split(".")[1:])]
    assert not private, f"private Hydra/OmegaConf modules imported: {private}"



#: The plan builder: the only modules that look a run's options up by name in the composed
#: configuration (everything after the plan reads its typed settings).
PLAN_BUILDER = ("nlosfw/pipeline/plan.py", "nlosfw/pipeline/plan_capture.py",
                "nlosfw/pipeline/plan_plugins.py", "nlosfw/pipeline/settings.py")
#: Calls that look an option up by its dotted name.
LOOKUPS = ("select", "_option")


def test_only_the_plan_builder_looks_options_up_by_name():
    """No module outside the plan builder reads an option of the composed configuration by
    its dotted name (``OmegaConf.select(cfg, "output.overwrite")``): it reads the plan's
    typed settings, so the plan is the one place an option's meaning is decided. Hydra's own
    keys (``hydra.run.dir``) are not the run's options."""
    found = []
    for path in _core_sources():
        where = str(path.relative_to(ROOT))
        if where in PLAN_BUILDER:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Call):
                continue
            name = (node.func.attr if isinstance(node.func, ast.Attribute) else
                    node.func.id if isinstance(node.func, ast.Name) else "")
            if name not in LOOKUPS:
                continue
            keys = [a.value for a in node.args if isinstance(a, ast.Constant)
                    and isinstance(a.value, str)]
            if name == "_option" or any(not k.startswith("hydra.") for k in keys):
                found.append(f"{where}:{node.lineno}: {ast.unparse(node)}")
    assert not found, f"options looked up by name outside the plan builder: {found}"


# ------------------------------------------------------------------ size and typing
#: The most uses of the word ``Any`` (outside import lines) nlosfw/ may hold: 349 before
#: the plugin boundary was typed; lower it when you remove more, never raise it.
MAX_ANY = 131
#: A module past MAX_MODULE_LINES is reviewed: split it where it holds two responsibilities,
#: or list it here with the one responsibility it holds (a line count alone is no reason
#: to split). Past MAX_LISTED_LINES a module is split whatever it holds.
ONE_RESPONSIBILITY: dict[str, str] = {
    "nlosfw/image/fft.py": "the fft imager: a volume's planes imaged by FFT convolution, "
                           "in frequency blocks or time slices",
    "nlosfw/pipeline/metrics.py": "the one definition of metrics.json: its typed sections, "
                                  "JSON in and out, its JSON Schema",
}
MAX_MODULE_LINES = 450
MAX_LISTED_LINES = 700
#: The largest share of nlosfw/'s lines one leaf package may hold (a package's modules,
#: not its subpackages': ``nlosfw.model`` and ``nlosfw.model.physics`` are measured apart).
MAX_PACKAGE_SHARE = 0.20


def _core_sources() -> list[Path]:
    return sorted(CORE.rglob("*.py"))


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_any_stays_rare():
    """``Any`` at the plugin boundary and in the stages is replaced by real types; a new
    use needs a reason (count as ``grep -rwn Any nlosfw | grep -v import``)."""
    word = re.compile(r"\bAny\b")
    uses = [f"{path.relative_to(ROOT)}:{number}"
            for path in _core_sources()
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
            if word.search(line) and "import" not in line]
    assert len(uses) <= MAX_ANY, (f"{len(uses)} uses of Any in nlosfw/, at most {MAX_ANY}; "
                                  f"type the new ones (last: {uses[-3:]})")


def test_no_module_is_over_the_size_limit():
    over = {str(path.relative_to(ROOT)): _lines(path) for path in _core_sources()
            if _lines(path) > MAX_MODULE_LINES}
    unlisted = {p: n for p, n in over.items() if p not in ONE_RESPONSIBILITY}
    assert not unlisted, (f"modules over {MAX_MODULE_LINES} lines: split each where it holds "
                          f"two responsibilities, or list it in ONE_RESPONSIBILITY with the "
                          f"one it holds: {unlisted}")
    too_long = {p: n for p, n in over.items() if n > MAX_LISTED_LINES}
    assert not too_long, f"modules over {MAX_LISTED_LINES} lines: {too_long}"
    stale = sorted(set(ONE_RESPONSIBILITY) - set(over))
    assert not stale, f"ONE_RESPONSIBILITY lists modules no longer over the limit: {stale}"


def _leaf_package(path: Path) -> str:
    """The package whose own module ``path`` is (``model.physics``; ``(top level)`` for
    nlosfw/'s own modules)."""
    return ".".join(path.relative_to(CORE).parts[:-1]) or "(top level)"


def test_no_package_holds_more_than_a_fifth_of_the_lines():
    sizes: dict[str, int] = {}
    for path in _core_sources():
        package = _leaf_package(path)
        sizes[package] = sizes.get(package, 0) + _lines(path)
    total = sum(sizes.values())
    shares = {p: round(n / total, 3) for p, n in sizes.items() if n / total > MAX_PACKAGE_SHARE}
    assert not shares, f"packages over {MAX_PACKAGE_SHARE:.0%} of nlosfw/'s lines: {shares}"


def test_every_package_is_listed_in_pyproject():
    """A package (a folder of nlosfw/ or conf/ with an ``__init__.py``) missing from
    pyproject.toml's ``packages`` would be left out of a non-editable install."""
    try:
        import tomllib
    except ModuleNotFoundError:        # Python 3.10
        tomllib = pytest.importorskip("tomli")
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))[
        "tool"]["setuptools"]
    found = {".".join(("nlosfw", *init.parent.relative_to(CORE).parts))
             for init in CORE.rglob("__init__.py")}
    found |= {".".join(("nlosfw.conf", *init.parent.relative_to(ROOT / "conf").parts))
              for init in (ROOT / "conf").rglob("__init__.py")}
    listed = set(setuptools["packages"])
    assert found - listed == set(), f"packages missing from pyproject.toml: {found - listed}"
    assert listed - found == set(), f"pyproject.toml lists no such package: {listed - found}"


def test_hook_specifications_keep_their_signatures():
    """Third-party plugins implement these hooks: names and parameters never change (their
    annotations may become more precise)."""
    import inspect

    from nlosfw.plugins import hookspecs

    expected = {
        "register_simulators": ["register"], "register_phasor_transforms": ["register"],
        "register_field_models": ["register"], "register_networks": ["register"],
        "register_imagers": ["register"], "register_capture_formats": ["register"],
        "register_array_backends": ["register"],
        "on_run_start": ["run_dir", "config"], "on_run_end": ["run_dir", "metrics", "status"],
        "on_stage_start": ["stage"], "on_stage_end": ["stage", "seconds"],
        "on_stage_result": ["stage", "result"], "on_progress": ["task", "done", "total", "info"],
        "on_training_step": ["source", "model", "step", "total_steps", "loss", "val_loss"],
        "on_artefact_written": ["path", "kind"],
        "write_run_report": ["files", "results", "metrics", "settings"],
        "write_capture_report": ["files", "capture", "depth_range", "metrics", "settings"],
        "write_run_page": ["files", "metrics", "config"],
    }
    found = {name: list(inspect.signature(fn).parameters)
             for name, fn in vars(hookspecs).items()
             if callable(fn) and hasattr(fn, "nlosfw_spec")}
    assert found == expected


# ------------------------------------------------------------------ names
#: Where no file may name an issue by number: a comment, docstring, test or option says
#: what the code does or guarantees, never which tracker entry asked for it.
NO_ISSUE_NUMBERS = ("nlosfw", "plugins", "conf", "tests", "examples", ".ci", "docs",
                    "benchmarks", "studies", "README.md", "CONTRIBUTING.md", "CHANGELOG.md",
                    "mkdocs.yml", "pyproject.toml", "dev.py")
ISSUE_NUMBER = re.compile(r"\bissues?[\s_-]*#?[0-9]+", re.IGNORECASE)


def _tracked_files(paths: tuple[str, ...]) -> list[Path]:
    """The files git tracks under ``paths`` (every file there, less build outputs, where
    the tree is not a git checkout)."""
    try:
        listed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--", *paths],
                                capture_output=True, check=True, timeout=60).stdout
        return [ROOT / name for name in listed.decode().split("\0") if name]
    except (OSError, subprocess.SubprocessError):
        skip = {".venv", "build", "__pycache__", ".git", ".pytest_cache", ".mypy_cache"}
        found = [p for path in paths for p in ([ROOT / path] if (ROOT / path).is_file()
                                               else (ROOT / path).rglob("*"))]
        return [p for p in found if p.is_file()
                and not skip & set(p.relative_to(ROOT).parts)
                and not any(part.endswith(".egg-info") for part in p.parts)]


def test_no_file_names_an_issue_by_number():
    files = _tracked_files(NO_ISSUE_NUMBERS)
    assert len(files) > 100, f"found only {len(files)} files to check under {NO_ISSUE_NUMBERS}"
    named = [f"{path.relative_to(ROOT)}:{number}: {match.group()}"
             for path in files if path.is_file()
             for number, line in enumerate(
                 path.read_bytes().decode("utf-8", "replace").splitlines(), 1)
             for match in ISSUE_NUMBER.finditer(line)]
    named += [f"{path.relative_to(ROOT)} (its name)" for path in files
              if ISSUE_NUMBER.search(path.relative_to(ROOT).as_posix())]
    assert not named, ("say what the code does or guarantees instead of which issue asked "
                       f"for it: {named}")
