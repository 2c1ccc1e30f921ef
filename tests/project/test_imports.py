"""What ``import nlosfw`` and ``python -m nlosfw plugins`` load: no UI, plotting, Hydra or
heavy backend (each checked in a fresh interpreter, on ``sys.modules``), and every public
name of a lazy package still resolves to its module's object."""

import importlib
import json
import os
import subprocess
import sys

import pytest

FORBIDDEN = ("matplotlib", "hydra", "omegaconf", "rich", "torch", "jax", "jaxlib", "mitsuba",
             "drjit", "embreex")


def _loaded_after(code: str) -> list[str]:
    probe = (f"{code}\nimport json, sys\n"
             f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}})))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         timeout=300, env={**os.environ, "COLUMNS": "200"})
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_nlosfw_loads_no_other_package():
    loaded = _loaded_after("import nlosfw")
    assert not set(loaded) & {*FORBIDDEN, "numpy", "scipy", "h5py", "msgspec", "pluggy"}, loaded


def test_plugins_listing_loads_no_ui_plotting_hydra_or_backend():
    loaded = _loaded_after("from nlosfw.cli import main\nmain(['plugins'])")
    assert not set(loaded) & {*FORBIDDEN, "scipy", "h5py"}, loaded


def test_a_public_name_wins_over_the_submodule_it_shares_its_name_with():
    # nlosfw.capture.preprocess is a function and a module: importing the module (as the
    # capture formats do) must not replace the function, as with eager imports
    code = ("import nlosfw.capture.formats, nlosfw.transform.fft\n"
            "import nlosfw.capture, nlosfw.transform\n"
            "from nlosfw.capture import preprocess\n"
            "assert callable(preprocess) and callable(nlosfw.transform.temporal_dft)")
    assert "nlosfw" in _loaded_after(code)


LAZY_PACKAGES = ["nlosfw", "nlosfw.capture", "nlosfw.simulate", "nlosfw.transform", "nlosfw.model",
                 "nlosfw.model.neural", "nlosfw.model.physics", "nlosfw.model.hybrid",
                 "nlosfw.image", "nlosfw.pipeline", "nlosfw.report"]


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_lazy_public_names_resolve_to_their_modules_objects(package):
    from nlosfw.common.lazy import lazy_exports

    module = importlib.import_module(package)
    names = set(module.__all__)
    assert names <= set(dir(module))
    for name in sorted(names):
        assert getattr(module, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        module.no_such_name  # noqa: B018
    getattr_, _ = lazy_exports(package, module.__file__)
    first = sorted(names)[0]
    assert getattr_(first) is getattr(module, first)
