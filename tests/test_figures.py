"""A run's figures say what ran and how they are seen, share one colour scale per row, and
have colorbars and axes in metres."""


from pathlib import Path

import msgspec
import numpy as np
import pytest

import nlosfw
from nlosfw.pipeline.results import CaptureResult
from nlosfw.report.figures import (
    VIEWPOINT,
    field_figure,
    reconstruction_figure,
    run_title,
    source_labels,
)

#: The run writes every kind of figure (test_run_writes_every_figure checks the names), at a
#: small dpi and with one single-frequency pair: the tests that look inside a figure draw
#: it again themselves, and drawing the files is most of the run's time.
TINY = ["scene=tiny", "model=interp", "+compare.nn={name:nearest}",
        "transform.n_frequencies=21", "reconstruction.n_depths=4", "figures.dpi=40",
        "reconstruction.single_frequency_images=1"]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("figures")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(root / "cache"))
        return nlosfw.run(TINY, output_dir=root / "run")


def _images(ax):
    return ax.get_images()


def test_reconstruction_figure_names_the_run_and_the_viewpoint(tiny_run):
    results = tiny_run.results
    title = run_title(tiny_run.metrics.run, results.capture)
    assert title == "scene tiny (simulator analytic) · model interp · imager fft"
    fig = reconstruction_figure(results.reconstructions.by_source,
                                tiny_run.metrics.reconstruction.sources,
                                results.capture.truth_depth, title, source_labels(results))
    suptitle = fig.get_suptitle()
    assert title in suptitle and VIEWPOINT in suptitle
    n = len(results.reconstructions.by_source)
    panels, colorbars = fig.axes[:3 * n], fig.axes[3 * n:]
    assert n == 4 and len(colorbars) == 3                 # one colorbar per row
    titles = [ax.get_title() for ax in panels[:n]]
    assert titles[0] == "true field" and titles[1].startswith("raw (training samples)\nPSNR ")
    assert titles[3].startswith("nn (nearest)\nPSNR") and titles[3].endswith(" vs true")
    for ax in panels:
        assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"


def test_side_by_side_panels_share_one_colour_scale_per_row(tiny_run):
    results = tiny_run.results
    recons = results.reconstructions.by_source
    fig = reconstruction_figure(recons, tiny_run.metrics.reconstruction.sources,
                                results.capture.truth_depth, "t", source_labels(results))
    n = len(recons)
    rows = [fig.axes[r * n:(r + 1) * n] for r in range(3)]
    intensity = [_images(ax)[0].get_clim() for ax in rows[0]]
    assert intensity == [(0.0, 1.0)] * n
    depths = tiny_run.metrics.reconstruction.depths
    assert [_images(ax)[0].get_clim() for ax in rows[1]] == [(min(depths), max(depths))] * n
    truth = _images(rows[2][0])[0]                       # ground truth on the depth scale
    assert truth.get_clim() == (min(depths), max(depths))
    errors = {_images(ax)[0].get_clim() for ax in rows[2][1:]}
    assert len(errors) == 1 and next(iter(errors))[1] > 0
    # the images cover the voxels' extent in metres
    voxels = results.reconstructions.voxels
    x0, x1, y0, y1 = _images(rows[0][0])[0].get_extent()
    assert (x0, x1) == (voxels[0, 0, 0, 0], voxels[0, 0, -1, 0])
    assert (y0, y1) == (voxels[0, 0, 0, 1], voxels[0, -1, 0, 1])


def test_field_figure_columns_share_one_scale(tiny_run):
    results = tiny_run.results
    fields = results.fields.by_source()
    fig = field_figure(fields, 5, "t", source_labels(results))
    n = len(fields)
    panels = np.array(fig.axes[:3 * n]).reshape(n, 3)
    assert len(fig.axes) == 3 * n + 3
    assert {_images(ax)[0].get_clim() for ax in panels[:, 0]} == {(0.0, 1.0)}
    assert {_images(ax)[0].get_clim() for ax in panels[:, 1]} == {(-np.pi, np.pi)}
    assert len({_images(ax)[0].get_clim() for ax in panels[2:, 2]}) == 1
    assert not _images(panels[0, 2]) and not _images(panels[1, 2])   # true, raw: no error
    freq = fields["true"].frequencies[5]
    assert f"f = {freq:.3f} cycles/m" in fig.get_suptitle()


def test_run_title_names_a_capture_file():
    from nlosfw.pipeline.metrics import RunInfo

    info = RunInfo(dir="d", nlosfw_version="0", started="now", config_hash="h", scene=None,
                   simulator=None, transform="fft", model="siren_torch", imager="rsd")
    capture = CaptureResult(capture=None, key="k", source="file",  # type: ignore[arg-type]
                            label="bike.hdf5 (ytal)", path=Path("/data/bike.hdf5"),
                            format="ytal")
    assert run_title(info, capture) == ("capture bike.hdf5 (format ytal) · model siren_torch · "
                                        "imager rsd")
    # model=none: the capture and the imager, the format not mistaken for the imager
    alone = msgspec.structs.replace(info, model="none", imager="fft")
    assert run_title(alone, capture) == "capture bike.hdf5 (format ytal) · imager fft"


def test_run_writes_every_figure(tiny_run):
    names = sorted(p.name for p in (tiny_run.dir / "figures").iterdir())
    singles = [s.index for s in tiny_run.results.reconstructions.single_frequency]
    views = [f"{view}_{source}.png" for source in tiny_run.results.reconstructions.by_source
             for view in ("front", "depth", "slices")]
    assert names == sorted(["reconstructions.png", *(f"fields_f{i}.png" for i in singles),
                            *(f"reconstructions_f{i}.png" for i in singles), *views,
                            "time_profile.png"])


def test_time_profile_counts_read_as_plain_numbers():
    """The figures' text is shown literally (no maths parser), so the counts' axis must not
    be labelled in maths markup: ``$\\mathdefault{10^{4}}$`` showed raw."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from nlosfw.report.plain_text import literal_text
    from nlosfw.report.views import time_profile_figure
    from nlosfw.testing.fixtures import tiny_capture

    fig = literal_text(time_profile_figure(tiny_capture(), (0.3, 0.6), "a title"))
    FigureCanvasAgg(fig).draw()
    labels = [t.get_text() for t in fig.axes[0].get_yticklabels() if t.get_text()]
    assert labels and not any("$" in label or "mathdefault" in label for label in labels)
    assert all(float(label) >= 0 for label in labels)
