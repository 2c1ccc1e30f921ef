"""Figures draw untrusted text (scene, file, model, compare and override names) literally,
and keep matplotlib's own labels: a log axis reads 10⁵, never ``$\\mathdefault{10^{5}}$``.

Each figure is checked as the run or the sweep writes it (``savefig`` is watched), or as
its figure function makes it, drawn: what every text shows (``Text._preprocess_math``,
what matplotlib draws from a text) and whether it is drawn as maths.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

import nlosfw
from nlosfw.report.figures import loss_figure
from nlosfw.report.quality import QualityPoint, SweepLayout, quality_figure
from nlosfw.report.study import Stat, StudyRow, study_figure
from nlosfw.report.views import write_views

#: Untrusted text: maths, rich markup, HTML.
UNTRUSTED = "$x$ [/] <b>"


def _shown(text: Text) -> tuple[str, bool]:
    """What matplotlib draws for ``text``, and whether it draws it as maths."""
    return text._preprocess_math(text.get_text())


def _texts(fig: Figure) -> list[Text]:
    return [t for t in fig.findobj(Text) if t.get_text()]


def _drawn(fig: Figure) -> Figure:
    FigureCanvasAgg(fig).draw()       # lays the figure out: the tick labels get their text
    return fig


def _assert_literal(fig: Figure, expected: int) -> None:
    """``UNTRUSTED`` is drawn literally in at least ``expected`` texts, never as maths."""
    literal = 0
    for text in _texts(fig):
        shown, maths = _shown(text)
        if "[/] <b>" in text.get_text():
            assert not maths and UNTRUSTED in shown, (text.get_text(), shown)
            literal += 1
    assert literal >= expected


def _assert_maths_ticks(ticks: list[Text]) -> list[str]:
    """The log axis's tick labels are maths (10⁵): their mathtext sources."""
    labels = [t for t in ticks if t.get_text()]
    assert labels
    for label in labels:
        shown, maths = _shown(label)
        assert maths and label.get_parse_math(), f"tick label drawn as text: {shown!r}"
    return [t.get_text() for t in labels]


class _Files:
    """The ``write(name, writer, kind)`` of a run's files, into a plain folder."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def write(self, name: str, writer, kind: str | None = None) -> Path:
        path = self.root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        writer(path)
        return path


@pytest.fixture
def saved(monkeypatch):
    """Every figure saved, by file name, after it was drawn into its file."""
    figures: dict[str, Figure] = {}
    original = Figure.savefig

    def record(fig: Figure, path, *args, **kwargs):
        original(fig, path, *args, **kwargs)
        figures[Path(path).name] = fig

    monkeypatch.setattr(Figure, "savefig", record)
    return figures


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("figure-text")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(root / "cache"))
        return nlosfw.run(["scene=tiny", "model=interp", "transform.n_frequencies=21",
                           "reconstruction.n_depths=4", "figures.enabled=false"],
                          output_dir=root / "run")


def test_the_time_profile_reads_powers_of_ten_and_untrusted_names_literally(tiny_run, tmp_path,
                                                                          saved):
    results = tiny_run.results
    recons = results.reconstructions.by_source
    write_views(_Files(tmp_path), recons, dict.fromkeys(recons, UNTRUSTED),
                results.capture.capture, f"scene {UNTRUSTED}", dpi=30)
    profile = saved["time_profile.png"]
    ticks = _assert_maths_ticks(profile.axes[0].get_yticklabels())
    assert any(t.startswith(r"$\mathdefault{10^{") for t in ticks), ticks
    from matplotlib.text import Text

    heading = [t for t in profile.findobj(Text) if "time profile" in t.get_text()]
    shown, maths = _shown(heading[0])
    assert len(heading) == 1 and shown.endswith(f"scene {UNTRUSTED}") and not maths
    assert len(saved) == 1 + 3 * len(recons)
    for fig in saved.values():
        _assert_literal(fig, expected=1)


def test_the_loss_figure_keeps_its_log_axis_and_shows_source_names_literally():
    history = [{"step": i, "loss": 10.0 ** -i, "val_loss": 2 * 10.0 ** -i} for i in range(6)]
    fig = _drawn(loss_figure({UNTRUSTED: history}, f"scene {UNTRUSTED}"))
    _assert_maths_ticks(fig.axes[0].get_yticklabels())
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert [_shown(t) for t in fig.axes[0].get_legend().get_texts()] == [
        (f"{UNTRUSTED} train", False), (f"{UNTRUSTED} validation", False)], legend
    _assert_literal(fig, expected=3)


@pytest.mark.parametrize("xs", [("1", "10", "100"), (UNTRUSTED, "b")],
                         ids=["log-x", "categories"])
def test_the_quality_figure_shows_swept_values_and_series_literally(xs):
    layout = SweepLayout(x=f"+compare.{UNTRUSTED}", facets=(f"scene.{UNTRUSTED}",))
    points = [QualityPoint(f"scene.{UNTRUSTED}={UNTRUSTED}", series, x, "ssim", (0.5 + i / 10,))
              for i, x in enumerate(xs) for series in (UNTRUSTED, "interp")]
    fig = _drawn(quality_figure(points, layout))
    ax = fig.axes[0]
    assert ax.get_xscale() == ("log" if xs[0] == "1" else "linear")
    assert [_shown(t) for t in ax.get_xticklabels()] == [(x, False) for x in xs]
    _assert_literal(fig, expected=4)    # the x label, the facet, a line, the suptitle


def test_the_study_figure_shows_conditions_and_series_literally(tmp_path, saved):
    def row(series: str, kind: str, under: float) -> StudyRow:
        scores = {key: Stat.of([0.5 / under]) for key in ("psnr", "ssim", "depth_rmse_m")}
        scores["heldout_excess_db"] = Stat.of([None])
        return StudyRow(condition=f"capture {UNTRUSTED}.hdf5", pattern="grid",
                        undersampling=under, train_samples=int(64 / under), series=series,
                        kind=kind, runs=1, seeds=(1,), scores=scores)

    rows = [row(s, k, u) for u in (2.0, 4.0) for s, k in ((UNTRUSTED, "model"),
                                                         ("interp", "baseline"))]
    study_figure(rows, tmp_path / "study.png", dpi=30)
    fig = saved["study.png"]
    assert [t for t in np.ravel(fig.axes) if t.get_xscale() == "log"]
    _assert_literal(fig, expected=2)    # the condition, the model's line in the legend
