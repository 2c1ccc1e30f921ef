"""Resources a hostile configuration or file makes a run take before it is refused.

A neural network's weights, their gradients and Adam's two moments are counted in the
memory estimate from the network's own description (its config's ``network_shapes``), so
a run whose networks cannot fit is refused in one line before anything is allocated.
A capture's datasets are checked against the shapes their format defines from their
headers, before any of them is read, and hints are read only when small: a tiny file
declaring a huge dataset of the wrong shape is refused in one line, its memory never
taken. Memory is measured in a fresh process (``ru_maxrss``), with its address space
limited so that a regression fails here instead of exhausting the machine.
"""

from __future__ import annotations

import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import ConfigError
from nlosfw.model.inr_networks import (
    FIELD_NETWORKS,
    HashGridFieldConfig,
    field_network_state,
    hash_grid_layout,
)
from nlosfw.model.neural_config import FieldMode, FieldShape
from nlosfw.model.thesis_networks import (
    THESIS_NETWORKS,
    THESIS_TEST_CONFIG,
    reference_state,
    thesis_architecture,
)
from nlosfw.pipeline import model_budget
from nlosfw.pipeline.budget import check_memory, estimate_memory
from nlosfw.plugins import load_plugins

GB = 1_000_000_000
#: The address space a measured process may take: enough for Python, numpy, h5py and
#: nlosfw, far less than what the hostile inputs would make it allocate.
ADDRESS_LIMIT = 6 * GB


def measured(code: str, *args: str, cwd: Path | None = None) -> tuple[int, str, int]:
    """Run ``code`` in a fresh Python (``sys.argv[1:]`` = ``args``) with its address space
    limited; (exit status, stderr, bytes its resident memory grew by after the code's
    ``BASE = ...`` line: the imports left out)."""
    script = textwrap.dedent("""
        import resource, sys
        def rss():
            return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        status = 0
        try:
    """) + textwrap.indent(textwrap.dedent(code), "    ") + textwrap.dedent("""
        finally:
            sys.stderr.write(f"\\nGROWN {rss() - BASE}\\n")
        sys.exit(status)
    """)

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_LIMIT, ADDRESS_LIMIT))

    done = subprocess.run([sys.executable, "-c", script, *args], capture_output=True,
                          text=True, timeout=600, preexec_fn=limit, cwd=cwd, check=False)
    lines = done.stderr.strip().splitlines()
    assert lines and lines[-1].startswith("GROWN "), done.stderr
    return done.returncode, "\n".join(lines[:-1]), int(lines[-1].split()[1])


# ======================================================= networks in the memory estimate
TINY = {"scene": {"wall": {"resolution": [16, 16]}, "time": {"bins": 512}},
        "transform": {"name": "fft", "n_frequencies": 21},
        "reconstruction": {"n_depths": 4}}


@pytest.fixture(scope="module")
def catalogue():
    return model_budget.plugin_requires(load_plugins())


def _parameters(config, catalogue):
    parts = {p.what: p for p in estimate_memory(config, requires=catalogue)}
    return parts.get("the networks' parameters")


def test_two_layers_of_50000_units_are_refused_for_their_weights(catalogue):
    """The named example: model.hidden=[50000,50000] (a small batch keeps the activations
    small) was estimated at about 340 MB and then allocated 10 GB per weight matrix."""
    config = {**TINY, "model": {"name": "siren_torch", "hidden": [50000, 50000],
                                "batch_size": 16}}
    weights = 3 * 50000 + 50000 + 50000 * 50000 + 50000 + 50000 * 2 + 2
    part = _parameters(config, catalogue)
    assert part is not None and part.nbytes == 36.0 * weights      # torch: 36 B a parameter
    assert part.why.startswith(f"model (siren_torch): {weights:,} parameters")
    with pytest.raises(ConfigError) as caught:
        check_memory(config, available=64 * GB, requires=catalogue)
    text = str(caught.value)
    assert "\n" not in text and "most of it for the networks' parameters" in text
    assert "90.0 GB)" in text and "but 64.0 GB are available" in text


@pytest.mark.parametrize(("name", "hidden", "bytes_each"), [("siren_torch", [20000, 20000], 36),
                                                            ("siren_jax", [20000, 20000], 30)])
def test_the_command_line_refuses_it_before_anything_is_allocated(workdir, name, hidden,
                                                                  bytes_each):
    """400 million parameters: 14 GB with torch, 12 GB with JAX, refused in one line (exit
    2) by a process that never grows past the checks (limited to 6 GB of address space: a
    regression fails here, it cannot exhaust the machine)."""
    status, err, grown = measured("""
        from nlosfw.cli import main
        from nlosfw.pipeline import budget
        budget.available_memory = lambda: 10_000_000_000
        BASE = rss()
        status = main(sys.argv[1:])
    """, "scene=tiny", f"model={name}", f"model.hidden={hidden}", "model.batch_size=16",
        "model.steps=1", "figures.enabled=false", cwd=workdir)
    assert status == 2, err
    line = [x for x in err.splitlines() if x.startswith("error:")]
    assert len(line) == 1 and "Traceback" not in err, err
    assert "most of it for the networks' parameters (model (" + name in line[0]
    assert "but 10.0 GB are available" in line[0]
    # composing and checking the configuration takes about 260 MB (Hydra, the plugins);
    # one of the weight matrices alone is 1.6 GB
    assert grown < GB, f"grew {grown / 1e6:.0f} MB before the refusal"
    assert not (workdir / "outputs").exists()
    assert bytes_each == model_budget.BACKENDS[name.split("_")[1]].per_parameter


def test_a_hash_grid_behind_a_small_network_is_counted(catalogue):
    """Not the widths: the neural volume's network is a hash grid whose 32 levels of 2^24
    rows of 16 features hold 8.6 billion parameters before one hidden layer of 8 units."""
    options = {"levels": 32, "features_per_level": 16, "log2_table_size": 24,
               "finest_resolution": 100000}
    config = {**TINY, "model": {"name": "neural_volume_torch", "network": "hashgrid",
                                "network_hidden": [8], "network_options": options}}
    part = _parameters(config, catalogue)
    layout = hash_grid_layout(HashGridFieldConfig(**options),
                              FieldShape(FieldMode.multi, (16, 16), 21))
    assert sum(layout.table_sizes) > 19 * 2**24               # 19 levels full, 13 smaller
    tables = sum(layout.table_sizes) * 16
    mlp = (32 * 16 + 1) * 8 + (8 + 1) * 2
    assert part is not None and part.nbytes == 36.0 * (tables + mlp)
    with pytest.raises(ConfigError, match=r"most of it for the networks' parameters \(model "
                                          r"\(neural_volume_torch\): 5,311,809,450 "):
        check_memory(config, available=64 * GB, requires=catalogue)


def test_single_mode_counts_one_network_per_frequency(catalogue):
    """pe_jax in single mode trains one network per frequency: 151 of 2.0 million."""
    config = {**TINY, "transform": {"name": "fft", "n_frequencies": 151},
              "model": {"name": "pe_jax", "mode": "single", "hidden": [1400, 1400],
                        "batch_size": 16, "octaves": 4}}
    per_network = (16 + 1) * 1400 + (1400 + 1) * 1400 + (1400 + 1) * 2
    part = _parameters(config, catalogue)
    assert part is not None and part.nbytes == 30.0 * 151 * per_network
    with pytest.raises(ConfigError, match=r"networks' parameters \(model \(pe_jax\): "
                                          r"300,188,302 parameters"):
        check_memory(config, available=8 * GB, requires=catalogue)
    multi = _parameters({**config, "model": {**config["model"], "mode": "multi"}}, catalogue)
    assert multi is not None and multi.nbytes < part.nbytes / 100


def test_the_residual_and_volume_networks_are_counted(catalogue):
    config = {**TINY, "model": {"name": "neural_volume_jax", "network": "fourier",
                                "network_hidden": [64], "network_options": {"features": 10}}}
    part = _parameters(config, catalogue)
    assert part is not None and part.nbytes == 30.0 * (3 * 10 + 20 * 64 + 64 + 64 * 2 + 2)
    config = {**TINY, "model": {"name": "rsd_residual_torch", "network": "wire",
                                "network_hidden": [30000, 30000]}}
    part = _parameters(config, catalogue)      # complex layers: two real numbers a weight
    complex_layer = 2 * (30000 * 30000 + 30000) + 2 * (30000 + 1)
    assert part is not None and part.nbytes == 36.0 * (3 * 30000 + 30000 + complex_layer)
    with pytest.raises(ConfigError, match=r"networks' parameters \(model "
                                          r"\(rsd_residual_torch\): 1,800,240,002 parameters"):
        check_memory(config, available=32 * GB, requires=catalogue)


def test_models_without_networks_add_no_parameters(catalogue):
    for name in ("interp", "rsd_prior", "nearest"):
        assert _parameters({**TINY, "model": {"name": name}}, catalogue) is None
    assert _parameters({**TINY, "model": {"name": "no_such_model"}}, catalogue) is None


@pytest.mark.parametrize("mode", ["multi", "single"])
def test_every_networks_shapes_are_its_initial_states(mode):
    """The description the estimate reads is the network itself: every array of every
    built-in network's initial state, by name and shape, at its defaults and test options."""
    shape = FieldShape(FieldMode(mode), (12, 9), 7)
    for name, network in THESIS_NETWORKS.items():
        for options in ({}, THESIS_TEST_CONFIG, {"octaves": 3, "hidden": [5, 6, 7]}):
            if "octaves" in options and name != "pe":
                continue
            config = config_from_mapping(network.config, {**options, "mode": mode})
            state = reference_state(thesis_architecture(config, shape), 0, 0)
            assert config.network_shapes(shape) == {k: v.shape for k, v in state.items()}
    for name, field_network in FIELD_NETWORKS.items():
        for options in ({}, field_network.test_config):
            config = config_from_mapping(field_network.config, {**options, "mode": mode})
            state = field_network_state(config, shape, 0, 0)
            assert config.network_shapes(shape) == {k: v.shape for k, v in state.items()}, \
                name


def test_counting_imports_no_backend():
    code = ("import sys; from nlosfw.plugins import load_plugins; "
            "from nlosfw.pipeline.model_budget import plugin_requires; "
            "from nlosfw.model.neural_config import FieldShape, FieldMode; "
            "r = plugin_requires(load_plugins()); s = FieldShape(FieldMode.multi, (8, 8), 5); "
            "print(r.parameters('siren_torch', {'hidden': [10]}, s), "
            "r.parameters('neural_volume_jax', {'network': 'hashgrid'}, s) > 0, "
            "'torch' in sys.modules, 'jax' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, check=True)
    assert done.stdout.split() == [str(3 * 10 + 10 + 10 * 2 + 2), "True", "False", "False"]
