"""The same configuration and seed on the CPU give byte-identical artefacts, except the
timing fields of metrics.json that nlosfw.pipeline.metrics.TIMING_FIELDS documents."""

from __future__ import annotations

import json
import re

import h5py

from nlosfw.pipeline.lifecycle import MARKER_NAME
from nlosfw.pipeline.metrics import TIMING_FIELDS, without_timings

#: A noisy scene (seeded draws), a neural model (seeded initialisation, saved weights) and
#: every figure: each kind of artefact a run writes.
RUN = ("scene=tiny", "scene.noise.model=poisson", "scene.noise.photons=1e5",
       "reconstruction.single_frequency_images=1",
       "model=siren_torch", "model.steps=30", "model.hidden=[16]",
       "imager=fft", "figures.enabled=true", "figures.dpi=40", "transform.n_frequencies=11",
       "reconstruction.n_depths=3", "cache.enabled=false", "hydra.run.dir=run",
       "output.keep=[capture,phasor_field,fields,model,reconstructions]")
#: Not artefacts: Hydra's records (they name the run's time), the log, the run's marker
#: (it names the process).
NOT_ARTEFACTS = (".hydra", "run.log", MARKER_NAME)


def artefacts(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and not set(p.relative_to(root).parts) & set(NOT_ARTEFACTS)}


def test_two_runs_write_the_same_bytes(workdir, tools):
    first = tools.run(*RUN)
    assert first.returncode == 0, first.stderr
    (workdir / "run").rename(workdir / "first")
    second = tools.run(*RUN)
    assert second.returncode == 0, second.stderr
    a, b = artefacts(workdir / "first"), artefacts(workdir / "run")
    assert set(a) == set(b)
    assert {"capture.hdf5", "phasor_field.hdf5", "field_model.npz", "fields/model.hdf5",
            "reconstructions/model.hdf5", "figures/reconstructions.png",
            "figures/loss.png"} <= set(a)
    differ = sorted(name for name in a if a[name] != b[name])
    # metrics.json for its timings and report.html, the page showing them; nothing else
    assert differ == ["metrics.json", "report.html"], differ
    numbers = re.compile(rb"\d+(?:\.\d+)?")    # the page's layout and words are the same
    assert numbers.sub(b"#", a["report.html"]) == numbers.sub(b"#", b["report.html"])
    ma, mb = json.loads(a["metrics.json"]), json.loads(b["metrics.json"])
    assert without_timings(ma) == without_timings(mb)
    assert ma["run"]["started"] and ma["timings"]["total"] > 0     # the fields dropped exist
    assert "run.started" in TIMING_FIELDS and "timings" in TIMING_FIELDS
    # HDF5 can stamp each dataset with its creation time; nlosfw's files must not
    for name in a:
        if name.endswith(".hdf5"):
            assert time_stamped(workdir / "run" / name) == [], name


def time_stamped(path) -> list[str]:
    """The datasets of an HDF5 file that record their creation time (a non-zero ctime in
    the object header: a reopened dataset's creation property list reports time tracking
    on whatever was stored, so it cannot tell)."""
    found: list[str] = []

    def visit(key, node) -> None:
        if isinstance(node, h5py.Dataset) and h5py.h5o.get_info(node.id).ctime != 0:
            found.append(key)

    with h5py.File(path) as f:
        f.visititems(visit)
    return found
