"""The FFT-based imagers estimate their own memory, and a run's plan counts it: the
padded volumes of lct, fk and fbp are most of what ``image FILE imager=lct`` holds (the
estimate left them out: a peak of twice to four times what the plan said)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from nlosfw.common.memory import PlanShape
from nlosfw.plugins import load_plugins
from nlosfw.testing import fixtures

N = 32
FREQUENCIES = np.linspace(0.5, 40.0, 80)
DEPTHS = np.linspace(0.3, 0.8, 30)
SHAPE = PlanShape(bins=1024, sensors=N * N, grid=(N, N), spacing=0.7 / N, confocal=True,
                  frequencies=FREQUENCIES.size, f_min=0.5, f_max=40.0, depth_range=(0.3, 0.8))


@pytest.mark.parametrize("name", ["fft", "lct", "fk", "fbp"])
def test_an_imager_estimates_the_memory_it_holds_within_1_5x(name):
    field = fixtures.point_field((0.05, -0.03, 0.5), (N, N), 0.7 / N, FREQUENCIES,
                                 confocal=True)
    voxels = fixtures.aligned_voxels(field.wall_xyz, DEPTHS)
    imager = load_plugins().registry.create("imager", name)
    estimate = type(imager).estimate_memory(imager.config, SHAPE, DEPTHS.size).total
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        imager.reconstruct(field, voxels)
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    assert estimate > 0
    assert 1 / 1.5 <= peak / estimate <= 1.5, (name, peak / 1e6, estimate / 1e6)


def test_the_plan_of_a_run_counts_its_imagers_memory():
    """The same run with lct estimates the light cone's volumes on top of fft's run."""
    from nlosfw.compose import plan_run

    base = ["scene=tiny", "model=none", "scene.capture.type=confocal",
            "figures.enabled=false"]
    host = load_plugins()
    totals = {}
    for name in ("fft", "lct"):
        memory = plan_run([*base, f"imager={name}"], host).memory
        parts = {part.what: part for part in memory.parts}
        totals[name] = memory.total
        if name == "lct":
            assert "the light-cone volumes" in parts
            assert parts["the light-cone volumes"].why.startswith("imager (lct): ")
    assert totals["lct"] > totals["fft"]
