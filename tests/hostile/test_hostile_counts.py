"""Degenerate photon counts: totals beyond what 64-bit integers hold, values beyond them
once scaled by a file's ``counts_per_unit``, and captures too empty to split. Count
splitting, the pile-up correction and the Poisson likelihood read a capture's counts
before the run starts; each of these ends there with one line naming the file, exit
status 2, and no run directory. The capture files are written here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from nlosfw.capture import photon_counts as counts_module
from nlosfw.capture.hdf5 import write_capture
from nlosfw.common.errors import DataError
from nlosfw.evaluation.count_splitting import capture_counts, split_counts
from nlosfw.testing.fixtures import tiny_capture

#: A run of a capture file that stops before anything slow: interp and the fast imager.
#: The most photons a capture may hold in all (2^53 - 1: every count and their sum exact
#: in float64, far from int64's end).
MAX_PHOTONS = 2**53 - 1

FILE_RUN = ("model=interp", "imager=fft", "figures.enabled=false", "transform.n_frequencies=21",
            "reconstruction.n_depths=4")


def no_output(workdir: Path) -> bool:
    return not (workdir / "outputs").exists() and not (workdir / "multirun").exists()


def refused(tools, workdir: Path, path: Path, *overrides: str) -> str:
    """The one error line of a run of capture ``path`` refused before it started (it names
    the file)."""
    result = tools.run(f"capture.path={path}", *FILE_RUN, *overrides)
    line = tools.one_error_line(result)
    assert result.returncode == 2, result.stderr
    assert str(path) in line, line
    assert no_output(workdir), "the run started"
    return line


def lct_file(folder: Path, rect_data: np.ndarray) -> Path:
    """A Stanford LCT .mat file (``rect_data`` [N, N, T] in its own integer type)."""
    path = folder / "counts.mat"
    scipy.io.savemat(path, {"rect_data": rect_data, "width": np.array([[0.5]])})
    return path


def ytal_file(folder: Path, H: np.ndarray, noise: dict | None = None) -> Path:
    """The tiny scene's capture (8 x 8 scan, 256 bins) with ``H`` and, if given, the
    ``scene_info.noise`` of a simulated capture of photon counts."""
    capture = tiny_capture(resolution=8)
    info = dict(capture.scene_info)
    if noise is not None:
        info["noise"] = noise
    path = folder / "scan.hdf5"
    write_capture(path, capture.replace(H=H.astype(H.dtype), scene_info=info))
    return path


# -------------------------------------------------------------- counts out of range
def test_int64_counts_near_2_to_the_60_are_refused_before_the_run(tools, workdir):
    """Each bin fits int64, their sum does not: the run completed with a negative photon
    total in metrics.json."""
    path = lct_file(workdir, np.full((4, 4, 64), 2**60 + 12345, dtype=np.int64))
    line = refused(tools, workdir, path, "split.count_splitting=true", "capture.gate.bins=0")
    assert line.startswith(f"error: {path}: ") and "split.count_splitting" in line
    assert f"{MAX_PHOTONS}" in line


def test_uint64_counts_above_2_to_the_63_are_refused_before_the_run(tools, workdir):
    """They ended the capture stage in ``ValueError: n < 0`` (the cast to int64 wrapped)."""
    path = lct_file(workdir, np.full((4, 4, 64), 2**63 + 2**62, dtype=np.uint64))
    line = refused(tools, workdir, path, "split.count_splitting=true", "capture.gate.bins=0")
    assert line.startswith(f"error: {path}: ")


def test_counts_per_unit_of_1e300_is_refused_before_the_run(tools, workdir):
    H = np.random.default_rng(0).poisson(2.0, (256, 8, 8)).astype(np.float32)
    path = ytal_file(workdir, H, {"model": "poisson", "counts_per_unit": 1e300})
    line = refused(tools, workdir, path, "split.count_splitting=true")
    assert line.startswith(f"error: {path}: ") and "counts per unit" in line


def test_pileup_correction_of_counts_beyond_int64_is_refused_before_the_run(tools, workdir):
    """The correction cast 1e19 counts to int64 and completed on what the cast made."""
    path = ytal_file(workdir, np.full((256, 8, 8), 1e19))
    line = refused(tools, workdir, path, "capture.pileup_pulses=1000000")
    assert line.startswith(f"error: {path}: ") and "capture.pileup_pulses" in line


def test_float_counts_whose_sum_is_beyond_int64_are_refused_before_the_run(tools, workdir):
    """2^50 photons a bin are exact float64 integers; 16,384 bins of them (2^64) wrapped."""
    path = ytal_file(workdir, np.full((256, 8, 8), 2.0**50))
    refused(tools, workdir, path, "split.count_splitting=true")


def test_the_poisson_likelihood_refuses_counts_beyond_int64_before_the_run(tools, workdir):
    path = ytal_file(workdir, np.full((256, 8, 8), 2.0**50))
    line = refused(tools, workdir, path, "model=rsd_prior", "model.likelihood=poisson",
                   "split.spectral=none")
    assert "model.likelihood" in line


def test_counts_up_to_the_limit_split_exactly():
    """The limit itself is accepted, and the halves' totals are exact integers there."""
    assert counts_module.MAX_PHOTONS == MAX_PHOTONS
    capture = tiny_capture(resolution=4, bins=256)
    H = np.zeros(capture.H.shape)
    H[0, 0, 0] = MAX_PHOTONS - 1
    H[1, 0, 0] = 1
    halves = split_counts(capture.replace(H=H), seed=0)
    assert halves.counts_a + halves.counts_b == MAX_PHOTONS
    assert halves.counts_a > 0 and halves.counts_b > 0
    H[1, 0, 0] = 2
    with pytest.raises(DataError, match="photon counts in all"):
        capture_counts(capture.replace(H=H), "scan.hdf5")


# -------------------------------------------------------------- too few photons
def zeros_with(photons: dict[tuple[int, int, int], int]) -> np.ndarray:
    H = np.zeros((256, 8, 8), dtype=np.float32)
    for where, n in photons.items():
        H[where] = n
    return H


@pytest.mark.parametrize("photons", [{}, {(100, 3, 3): 1}], ids=["no photon", "one photon"])
def test_a_capture_too_empty_to_split_is_refused_before_the_run(photons, tools, workdir):
    """Refused at the fit stage before, with the run directory written."""
    path = ytal_file(workdir, zeros_with(photons))
    line = refused(tools, workdir, path, "split.count_splitting=true")
    assert line.startswith(f"error: split.count_splitting: {path}: ")
    assert f"{sum(photons.values())} photon" in line


def test_photons_only_in_the_gated_bins_are_refused_before_the_run(tools, workdir):
    """The LCT format zeroes the first 600 bins by default: what is left holds none."""
    rect = np.zeros((4, 4, 640), dtype=np.uint16)
    rect[:, :, 10] = 50
    path = lct_file(workdir, rect)
    line = refused(tools, workdir, path, "split.count_splitting=true")
    assert "0 photons" in line


def test_a_split_that_leaves_a_half_empty_is_refused_before_the_run(tools, workdir):
    """Two photons: with some seeds both land in one half. The split is drawn before the
    run with the run's seed, and a seed that leaves a half empty is refused naming it."""
    capture = tiny_capture(resolution=8)
    H = zeros_with({(100, 3, 3): 1, (120, 4, 4): 1})
    seed = next(s for s in range(64)
                if 0 in (split_counts(capture.replace(H=H), s).counts_a,
                         split_counts(capture.replace(H=H), s).counts_b))
    path = ytal_file(workdir, H)
    line = refused(tools, workdir, path, "split.count_splitting=true",
                   f"split.count_splitting_seed={seed}")
    assert line.startswith(f"error: split.count_splitting_seed: {path}: ")

