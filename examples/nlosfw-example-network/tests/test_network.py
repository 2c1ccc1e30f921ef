"""The example network through nlosfw: its fixed matrix, its size, and the command line."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from nlosfw.common import ConfigError
from nlosfw.model import read_model_file
from nlosfw.plugins import load_plugins, registered_network, registered_networks
from nlosfw.testing import fixtures

pytest.importorskip("torch")

OPTIONS = {"steps": 40, "batch_size": 0, "features": 8, "hidden": [12, 10], "sigma": 2.0,
           "device": "cpu"}


def _model(**options):
    spec = load_plugins().registry.get("model", "example_fourier_torch")
    return spec.create({**OPTIONS, **options})


def _saved_state(model, path):
    model.save(path)
    return read_model_file(path, "example_fourier_torch")[1]


def test_fourier_matrix_is_saved_and_never_trained(tmp_path):
    field = fixtures.smooth_field(n=8, frequencies=np.linspace(2.0, 3.0, 4), seed=2)
    short, long = _model(steps=2), _model(steps=60)
    short.fit(field)
    long.fit(field)
    a, b = _saved_state(short, tmp_path / "a.npz"), _saved_state(long, tmp_path / "b.npz")
    assert a["B"].shape == (3, 8)                       # (x, y, f) -> 8 features
    np.testing.assert_array_equal(a["B"], b["B"])       # same seed, not trained
    assert np.std(a["B"]) == pytest.approx(2.0, rel=0.5)     # N(0, sigma^2), sigma = 2
    assert not np.allclose(a["mlp.0.weight"], b["mlp.0.weight"])   # the MLP is trained


def test_only_the_mlp_counts_as_parameters():
    model = _model()
    model.fit(fixtures.smooth_field(n=8, frequencies=np.linspace(2.0, 3.0, 4), seed=2))
    # 2 * 8 features -> 12 -> 10 -> 2, weights and biases; B is not a parameter
    assert model.n_parameters == (16 * 12 + 12) + (12 * 10 + 10) + (10 * 2 + 2)


def test_listed_among_the_torch_networks_and_found_by_name():
    """registered_networks lists the example beside torch's own networks (not for JAX,
    which it does not register for), and registered_network finds its field model; a
    wrong name's error lists the same names."""
    names = registered_networks("torch")
    assert "example_fourier" in names and names == sorted(names)
    assert "example_fourier" not in registered_networks("jax")
    assert registered_network("example_fourier", "torch").model_name() == \
        "example_fourier_torch"
    with pytest.raises(ConfigError, match="valid: " + ", ".join(names) + "$"):
        registered_network("no_such_network", "torch")


@pytest.mark.slow
def test_selectable_on_the_command_line(tmp_path):
    env = {**os.environ, "NLOSFW_CACHE_DIR": str(tmp_path / "cache")}
    # a short run: few steps, frequencies and depth planes (the plugin's options arrive, it
    # trains and the run completes; how well it fits is the conformance kit's check)
    args = ["scene=tiny", "model=example_fourier_torch", "model.steps=10", "model.sigma=2",
            "imager=fft", "figures.enabled=false", "transform.n_frequencies=21",
            "reconstruction.n_depths=4", "reconstruction.single_frequency_images=0"]
    result = subprocess.run([sys.executable, "-m", "nlosfw", *args], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=600, check=False)
    assert result.returncode == 0, result.stderr[-3000:]
    (metrics_file,) = (tmp_path / "outputs").glob("*/*/metrics.json")
    metrics = json.loads(metrics_file.read_text())
    assert metrics["status"] == "completed"
    assert metrics["field"]["model"]["plugin"] == "example_fourier_torch"
    assert metrics["field"]["model"]["fit"]["steps"] == 10
