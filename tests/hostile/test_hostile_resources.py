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

import h5py
import numpy as np
import pytest
import scipy.io

from nlosfw.capture.data import Capture
from nlosfw.capture.hdf5 import write_capture
from nlosfw.capture.source import read_capture_file
from nlosfw.common.config import config_from_mapping
from nlosfw.common.errors import ConfigError
from nlosfw.common.hdf5_guard import ANY_SHAPE, Expected
from nlosfw.model.neural import memory as neural_memory
from nlosfw.model.neural.catalogue import (
    FIELD_NETWORKS,
    THESIS_NETWORKS,
    THESIS_TEST_CONFIG,
    field_network_state,
)
from nlosfw.model.neural.config import FieldMode, FieldShape
from nlosfw.model.neural.mlp import reference_state, thesis_architecture
from nlosfw.pipeline.budget import check_memory
from nlosfw.plugins import load_plugins
from nlosfw.simulate.analytic import AnalyticSimulator
from nlosfw.simulate.scene import scene_from_config
from nlosfw.testing import fixtures, layouts
from tests.planned import TINY, planned

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
def _parameters(overrides):
    """The networks' parameters part of the plan of a tiny run with ``overrides``."""
    parts = {p.what: p for p in planned((*TINY[:-1], *overrides)).memory.parts}
    return parts.get("the networks' parameters")


def _memory(overrides):
    return planned((*TINY[:-1], *overrides)).memory


def test_two_layers_of_50000_units_are_refused_for_their_weights():
    """The named example: model.hidden=[50000,50000] (a small batch keeps the activations
    small) was estimated at about 340 MB and then allocated 10 GB per weight matrix."""
    overrides = ("model=siren_torch", "model.hidden=[50000,50000]", "model.batch_size=16")
    weights = 3 * 50000 + 50000 + 50000 * 50000 + 50000 + 50000 * 2 + 2
    part = _parameters(overrides)
    assert part is not None and part.nbytes == 36.0 * weights      # torch: 36 B a parameter
    assert part.why.startswith(f"model (siren_torch): {weights:,} parameters")
    with pytest.raises(ConfigError) as caught:
        check_memory(_memory(overrides), available=64 * GB)
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
    # composing and checking the configuration takes about 260 MB (Hydra, the plugins; the
    # plan imports the model's backend); one of the weight matrices alone is 1.6 GB
    assert grown < GB, f"grew {grown / 1e6:.0f} MB before the refusal"
    assert not (workdir / "outputs").exists()
    assert bytes_each == neural_memory.BACKENDS[name.split("_")[1]].per_parameter


def test_a_hash_grid_behind_a_small_network_is_counted():
    """Not the widths: the neural volume's network is a hash grid whose 32 levels of up to
    2^24 rows of 16 features hold billions of parameters before one hidden layer of 8."""
    options = ("model=neural_volume_torch", "model.network=hashgrid", "model.network_hidden=[8]",
               "+model.network_options={levels:32,features_per_level:16,log2_table_size:24,"
               "finest_resolution:100000}")
    part = _parameters(options)
    assert part is not None and part.nbytes > 36.0 * 16 * 19 * 2**24   # 19 levels full
    with pytest.raises(ConfigError, match=r"most of it for the networks' parameters \(model "
                                          r"\(neural_volume_torch\): [0-9,]{13} parameters"):
        check_memory(_memory(options), available=64 * GB)


def test_single_mode_counts_one_network_per_frequency():
    """pe_jax in single mode trains one network per frequency: 151 of 2.0 million."""
    single = ("transform.n_frequencies=151", "model=pe_jax", "model.mode=single",
              "model.hidden=[1400,1400]", "model.batch_size=16", "model.octaves=4")
    per_network = (16 + 1) * 1400 + (1400 + 1) * 1400 + (1400 + 1) * 2
    part = _parameters(single)
    assert part is not None and part.nbytes == 30.0 * 151 * per_network
    with pytest.raises(ConfigError, match=r"networks' parameters \(model \(pe_jax\): "
                                          r"300,188,302 parameters"):
        check_memory(_memory(single), available=8 * GB)
    multi = _parameters((*single[:2], "model.mode=multi", *single[3:]))
    assert multi is not None and multi.nbytes < part.nbytes / 100


def test_the_residual_and_volume_networks_are_counted():
    part = _parameters(("model=neural_volume_jax", "model.network=fourier",
                        "model.network_hidden=[64]", "+model.network_options={features:10}"))
    assert part is not None and part.nbytes == 30.0 * (3 * 10 + 20 * 64 + 64 + 64 * 2 + 2)
    residual = ("model=rsd_residual_torch", "model.network=wire",
                "model.network_hidden=[30000,30000]")
    part = _parameters(residual)      # complex layers: two real numbers a weight
    complex_layer = 2 * (30000 * 30000 + 30000) + 2 * (30000 + 1)
    assert part is not None and part.nbytes == 36.0 * (3 * 30000 + 30000 + complex_layer)
    with pytest.raises(ConfigError, match=r"networks' parameters \(model "
                                          r"\(rsd_residual_torch\): 1,800,240,002 parameters"):
        check_memory(_memory(residual), available=32 * GB)


def test_models_without_networks_add_no_parameters():
    for name in ("interp", "rsd_prior", "nearest"):
        assert _parameters((f"model={name}",)) is None


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


def test_counting_a_networks_parameters_allocates_nothing():
    """400 million parameters are counted from the network's description: nothing of
    their size is allocated, and no backend is imported to count them."""
    import tracemalloc

    from nlosfw.model.neural import SirenFieldConfig

    shape = FieldShape(FieldMode.multi, (8, 8), 5)
    code = ("import sys; from nlosfw.model.neural import SirenFieldConfig, FieldShape, "
            "FieldMode; from nlosfw.model.neural.memory import parameter_count; "
            "print(parameter_count(SirenFieldConfig(hidden=(10,)), "
            "FieldShape(FieldMode.multi, (8, 8), 5)), 'torch' in sys.modules, "
            "'jax' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=600, check=True)
    assert done.stdout.split() == [str(3 * 10 + 10 + 10 * 2 + 2), "False", "False"]
    tracemalloc.start()
    try:
        count = neural_memory.parameter_count(SirenFieldConfig(hidden=(20000, 20000)), shape)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert count == 3 * 20000 + 20000 + 20000 * 20000 + 20000 + 20000 * 2 + 2
    assert peak < 1_000_000


# ======================================================= datasets sized before they are read
MB = 1_000_000
#: What reading a refused file may add to a process: the file's headers and small fields.
READ_LIMIT = 100 * MB


def _simulated(scene: dict) -> Capture:
    return AnalyticSimulator().simulate(scene_from_config(scene))


def declare(path: Path, name: str, shape: tuple[int, ...], dtype: str = "f8") -> Path:
    """Replace dataset ``name`` of HDF5 file ``path`` by one that declares ``shape`` (HDF5's
    order) and stores nothing: a file of a few kB whose dataset reads as gigabytes."""
    with h5py.File(path, "a") as f:
        attrs = dict(f[name].attrs) if name in f else {}
        if name in f:
            del f[name]
        chunks = tuple(min(n, 64) for n in shape)
        node = f.create_dataset(name, shape=shape, dtype=dtype, chunks=chunks,
                                fillvalue=1.0)
        for key, value in attrs.items():
            node.attrs[key] = value
    assert path.stat().st_size < 1_000_000
    return path


def _ytal(folder: Path, nlosfw_attributes: bool = True) -> Path:
    return write_capture(folder / "c.hdf5", fixtures.tiny_capture(),
                         nlosfw_attributes=nlosfw_attributes)


def _wisconsin(folder: Path) -> Path:
    return layouts.write_wisconsin(folder / "w.mat", _simulated(layouts.wisconsin_scene()))


def _znlos(folder: Path) -> Path:
    return layouts.write_znlos(folder / "z.hdf5", _simulated(layouts.znlos_scene()))


def _lct(folder: Path) -> Path:
    data = np.zeros((8, 8, 64), np.float32)
    return layouts.write_mat73(folder / "data_x.mat", {"rect_data": data, "width": 0.5})


def _fk(folder: Path) -> Path:
    return layouts.write_mat73(folder / "meas_10min.mat",
                               {"meas": np.zeros((8, 8, 64), np.float32)})


#: format -> (its file, the dataset made huge, the shape it declares (HDF5's order), what
#: the refusal says); each file reads in full at 600 MB to 1.3 GB (or more as Python lists).
HUGE = {
    "nlosfw: sensor points": (_ytal, "sensor_grid_xyz", (5000, 5000, 3),
                              "declares shape [5000, 5000, 3]; expected 64 points of 3 "
                              "coordinates, as many as H's sensor axes [8, 8]"),
    "ytal: laser normals": (lambda d: _ytal(d, False), "laser_grid_normals", (4000, 7000, 3),
                            "expected one point of 3 coordinates (a single spot) or 64 "
                            "(confocal, H's sensor axes [8, 8])"),
    "ytal: H of the wrong rank": (lambda d: _ytal(d, False), "H", (256, 8, 8, 1200),
                                  "declares shape [256, 8, 8, 1200]; expected 3 axes "
                                  "(H_format T_Sx_Sy)"),
    "ytal: a scalar": (lambda d: _ytal(d, False), "delta_t", (100_000_000,),
                       "expected one number"),
    "znlos: camera grid": (_znlos, "cameraGridPositions", (3, 5000, 5000),
                           "expected 64 points of 3 coordinates, as many as data's sensor"),
    "znlos: volume hint": (_znlos, "hiddenVolumeSize", (100_000_000, 1),
                           "expected 1 or 3 numbers (a hint about the hidden volume)"),
    "znlos: data's order": (_znlos, "data", (1, 400, 2, 8, 8, 5000),
                            "expected 5 (confocal) or 7 axes in a known ZNLOS order"),
    "wisconsin: volume hint": (_wisconsin, "minimalpos", (20_000_000, 1),
                               "variable 'minimalpos' declares shape [1, 20000000]; "
                               "expected 1 or 3 numbers"),
    "wisconsin: laser positions": (_wisconsin, "dataset/laserPos", (3, 30_000_000),
                                   "variable 'dataset.laserPos' declares shape [30000000, 3]; "
                                   "expected 64 points n x 3 (or 3 x n), one per row of data"),
    "lct: not square": (_lct, "rect_data", (2048, 8000, 64),
                        "variable 'rect_data' declares shape [64, 8000, 2048]; expected a "
                        "square scan [N, N, T]"),
    "lct: width": (_lct, "width", (1, 100_000_000), "variable 'width' declares shape "
                                                    "[100000000, 1]; expected one number"),
}

READ = """
    from pathlib import Path
    from nlosfw.capture.source import read_capture_file
    from nlosfw.common.errors import NlosfwError
    from nlosfw.plugins import load_plugins
    formats = load_plugins().capture_formats()
    BASE = rss()
    try:
        read_capture_file(Path(sys.argv[1]), None, formats)
    except NlosfwError as err:
        sys.stderr.write(str(err))
        status = 2
"""


@pytest.mark.parametrize("case", sorted(HUGE))
def test_a_huge_dataset_of_the_wrong_shape_is_refused_from_its_header(tmp_path, case):
    """The named examples (a 53 kB file declaring a 3.2 GB sensor_grid_xyz of the wrong
    shape took 3.4 GB before being refused; a Wisconsin file's 160 MB volume hint became a
    1 GB Python list), and one dataset of each kind of every capture format."""
    write, name, shape, message = HUGE[case]
    path = declare(write(tmp_path), name, shape)
    status, err, grown = measured(READ, str(path))
    assert grown < READ_LIMIT, f"{case}: grew {grown / MB:.0f} MB before the refusal"
    assert status == 2, err
    assert err.count("\n") == 0 and err.startswith(f"{path}: "), err
    assert message in err and err.endswith("; refused before reading it"), err


def test_the_command_line_refuses_the_named_example_in_one_line(workdir):
    capture = write_capture(workdir / "c.hdf5", fixtures.tiny_capture())
    declare(capture, "sensor_grid_xyz", (20000, 20000, 1))          # 3.2 GB declared
    status, err, grown = measured("""
        from nlosfw.cli import main
        BASE = rss()
        status = main(sys.argv[1:])
    """, f"capture.path={capture}", "model=interp", "figures.enabled=false", cwd=workdir)
    assert status == 2 and "Traceback" not in err, err
    assert err.strip() == (f"error: {capture}: dataset 'sensor_grid_xyz' declares shape "
                           "[20000, 20000, 1]; expected 64 points of 3 coordinates, as many "
                           "as H's sensor axes [8, 8]; refused before reading it")
    assert grown < 400 * MB          # the checks take about 260 MB (Hydra, the plugins)
    assert not (workdir / "outputs").exists()


def test_a_tofgrid_of_another_grid_is_refused_before_it_is_read(tmp_path):
    """A 2-D tofgrid is read only when its header matches the scan grid it corrects."""
    meas = _fk(tmp_path)
    tof = layouts.write_mat73(tmp_path / "tof.mat", {"tofgrid": np.zeros((8, 8))})
    declare(tof, "tofgrid", (12000, 10000))                          # 960 MB declared
    status, err, grown = measured("""
        from pathlib import Path
        from nlosfw.capture.source import CaptureSource, load_file_capture
        from nlosfw.common.errors import NlosfwError
        from nlosfw.plugins import load_plugins
        formats = load_plugins().capture_formats()
        BASE = rss()
        try:
            load_file_capture(CaptureSource(path=sys.argv[1], tofgrid=sys.argv[2]), formats)
        except NlosfwError as err:
            sys.stderr.write(str(err))
            status = 2
    """, str(meas), str(tof))
    assert status == 2, err
    assert err == (f"capture.tofgrid: {tof}: variable 'tofgrid' has shape [10000, 12000]; "
                   f"expected [8, 8], the scan grid of {meas}")
    assert grown < READ_LIMIT, f"grew {grown / MB:.0f} MB before the refusal"


def test_a_matlab_5_variable_is_shaped_from_its_header(tmp_path):
    """A v5 file (scipy): its header's shape is checked before loadmat reads it. Listing a
    compressed variable costs scipy one block of its stream decompressed (about 264 MB at
    zlib's largest ratio, whatever the variable's size); the 800 MB are never read."""
    path = tmp_path / "tof.mat"
    subprocess.run([sys.executable, "-c", "import sys, numpy as np, scipy.io; "
                    "scipy.io.savemat(sys.argv[1], {'tofgrid': np.zeros((100, 1000, 1000))}, "
                    "format='5', do_compression=True)", str(path)], check=True, timeout=600)
    assert path.stat().st_size < 2 * MB
    status, err, grown = measured("""
        from pathlib import Path
        from nlosfw.capture.fk import read_tofgrid
        from nlosfw.common.errors import NlosfwError
        BASE = rss()
        try:
            read_tofgrid(Path(sys.argv[1]))
        except NlosfwError as err:
            sys.stderr.write(str(err))
            status = 2
    """, str(path))
    assert status == 2, err
    assert err == (f"{path}: variable 'tofgrid' declares shape [100, 1000, 1000]; expected "
                   "[N, N] (one delay in picoseconds per scan point); refused before reading "
                   "it")
    assert grown < 400 * MB, f"grew {grown / MB:.0f} MB before the refusal"


# ---------------------------------------- every dataset a format reads has a shape expected
class _Reads:
    """Which datasets were read, and which were checked against an expected shape first."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.read: list[str] = []
        self.checked: set[str] = set()
        check, getitem, loadmat = Expected.check, h5py.Dataset.__getitem__, scipy.io.loadmat

        def checked(expected, shape, path, where, noun="dataset"):
            if expected is not ANY_SHAPE:
                self.checked.add(where)
            return check(expected, shape, path, where, noun)

        def read(node, *args, **kwargs):
            self.read.append(node.name.strip("/").replace("/", "."))
            return getitem(node, *args, **kwargs)

        def load(name, *args, variable_names=None, **kwargs):
            self.read.extend(variable_names or ["<every variable>"])
            return loadmat(name, *args, variable_names=variable_names, **kwargs)

        monkeypatch.setattr(Expected, "check", checked)
        monkeypatch.setattr(h5py.Dataset, "__getitem__", read)
        monkeypatch.setattr(scipy.io, "loadmat", load)


SAMPLES = {
    "nlosfw": lambda d: _ytal(d),
    "ytal": lambda d: _ytal(d, False),
    "ytal fixture": lambda d: Path(__file__).parents[1] / "data" / "ytal_confocal.hdf5",
    "znlos fixture": lambda d: Path(__file__).parents[1] / "data" / "znlos_confocal.hdf5",
    "znlos": _znlos,
    "wisconsin": _wisconsin,
    "lct": lambda d: layouts.write_lct(d / "data_s.mat", _simulated(layouts.lct_scene())),
    "lct v5": lambda d: layouts.write_mat5(d / "data_v5.mat", {
        "rect_data": np.zeros((8, 8, 64), np.uint16), "width": np.array([[0.5]])}),
    "fk": lambda d: layouts.write_fk(d, _simulated(layouts.fk_scene()))[0],
}


@pytest.mark.parametrize("sample", sorted(SAMPLES))
def test_every_dataset_a_format_reads_was_checked_against_its_shape(tmp_path, monkeypatch,
                                                                     sample):
    path = SAMPLES[sample](tmp_path)
    catalogue = load_plugins().capture_formats()
    reads = _Reads(monkeypatch)
    read_capture_file(path, None, catalogue)
    assert reads.read, "nothing was read"
    unchecked = sorted(set(reads.read) - reads.checked)
    assert not unchecked, f"{sample}: read without an expected shape: {unchecked}"
