"""The sweep report's quality plot: the swept key on x, one line per model, interp and raw
on every panel, repeats (seeds) as mean and range, other swept keys as rows of panels."""

import itertools

import numpy as np
import pytest

from nlosfw.pipeline.metrics import (
    ErrorMetrics,
    FieldMetrics,
    FitMetrics,
    ImageScores,
    ReconstructionMetrics,
    RunInfo,
    RunMetrics,
    SplitErrors,
)
from nlosfw.report.quality import (
    quality_figure,
    quality_points,
    quality_table,
    sweep_layout,
)
from nlosfw.report.records import RunRecord


def _errors(nmse_db):
    e = ErrorMetrics(relative_l2=10 ** (nmse_db / 20), nmse_db=nmse_db, amplitude_rmse=None,
                     relative_amplitude_rmse=None, phase_error=None, n_samples=10)
    return SplitErrors(heldout_pixels=e, heldout_frequencies=e, all=e, heldout_pixels_inside=e)


def _entry(plugin, nmse_db):
    fit = FitMetrics(steps=1, seconds=1.0, final_loss=None, best_val_loss=None,
                     stopped_early=False)
    return FieldMetrics(plugin=plugin, n_parameters=1, training_values=1,
                        parameters_per_value=1.0, fit=fit, splits=_errors(nmse_db))


def record(name, overrides, model, ssim):
    """A run of field model ``model`` whose sources have the given SSIM (and NMSE = -10 SSIM)."""
    info = RunInfo(dir=name, nlosfw_version="0", started="now", config_hash="h", scene="s",
                   simulator="analytic", transform="fft", model=model, imager="fft")
    field = {("interp" if model == "interp" else "model"): _entry(model, -10 * ssim[model])}
    if model != "interp":
        field["interp"] = _entry("interp", -10 * ssim["interp"])
    sources = {"true": ImageScores(rmse=0.0, psnr=None, ssim=1.0, volume_psnr=None,
                                   volume_ssim=1.0),
               **{("model" if s == model != "interp" else s):
                  ImageScores(rmse=0.1, psnr=20 * v, ssim=v, volume_psnr=20 * v, volume_ssim=v)
                  for s, v in ssim.items()}}
    recon = ReconstructionMetrics(imager="fft", reference="true", depths=(1.0,),
                                  depth_planes=1, depth_spacing=None, sources=sources,
                                  single_frequency={})
    metrics = RunMetrics(status="completed", run=info, field=field, reconstruction=recon)
    return RunRecord(name=name, metrics=metrics, overrides=tuple(overrides))


def sparsity_sweep(seeds=(1,), scenes=("a",)):
    """model x split.spatial_step (x seeds x scenes); SSIM falls with the step."""
    runs = []
    for i, (scene, model, step, seed) in enumerate(itertools.product(
            scenes, ["siren_torch", "interp"], [2, 4, 8], seeds)):
        quality = {"siren_torch": 0.9, "interp": 0.8, "raw": 0.7}
        ssim = {k: v / step + 0.01 * seed for k, v in quality.items()}
        ssim = {k: v for k, v in ssim.items() if model != "interp" or k != "siren_torch"}
        overrides = [f"model={model}", f"split.spatial_step={step}", f"+model.seed={seed}",
                     f"scene={scene}", "figures.enabled=false"]
        runs.append(record(str(i), overrides, model, ssim))
    return runs


def test_layout_puts_the_numeric_swept_key_on_x_and_seeds_as_repeats():
    layout = sweep_layout(sparsity_sweep(seeds=(1, 2), scenes=("a", "b")))
    assert layout.x == "split.spatial_step"
    assert layout.repeats == ("model.seed",) and layout.facets == ("scene",)
    assert sweep_layout(sparsity_sweep(), x="scene").x == "scene"


def test_layout_of_a_sweep_over_models_only_puts_the_models_on_x():
    runs = [record(str(i), [f"model={m}"], m, {m: 0.9, "interp": 0.8, "raw": 0.7})
            for i, m in enumerate(["siren_torch", "pe_torch"])]
    assert sweep_layout(runs).x == "model"
    assert sweep_layout(runs[:1]).x is None          # nothing swept: one position per run


def test_points_have_one_line_per_model_and_the_baselines_at_every_x():
    runs = sparsity_sweep(seeds=(1, 2))
    layout = sweep_layout(runs)
    points = quality_points(runs, layout)
    ssim = {(p.series, p.x): p for p in points if p.metric == "ssim"}
    assert {s for s, _ in ssim} == {"siren_torch", "interp", "raw"}
    for x in ("2", "4", "8"):
        assert {("siren_torch", x), ("interp", x), ("raw", x)} <= set(ssim)
    # seeds 1 and 2 are repeats: two values, mean in between
    siren = ssim[("siren_torch", "4")]
    assert siren.values == pytest.approx((0.9 / 4 + 0.01, 0.9 / 4 + 0.02))
    assert siren.mean == pytest.approx(0.9 / 4 + 0.015)
    # interp is imaged in every run (4 per x: 2 models x 2 seeds); raw has no field error
    assert len(ssim[("interp", "2")].values) == 4
    nmse = {p.series for p in points if p.metric == "heldout_nmse_db"}
    assert nmse == {"siren_torch", "interp"}


def test_figure_has_every_line_on_every_panel_and_the_x_values_as_ticks():
    runs = sparsity_sweep(scenes=("a", "b"))
    layout = sweep_layout(runs)
    fig = quality_figure(quality_points(runs, layout), layout)
    panels = [ax for ax in fig.axes if ax.get_xlabel() == "split.spatial_step"]
    assert len(panels) == 2 * 3                      # two scenes x (SSIM, PSNR, NMSE)
    for ax in panels:
        labels = set(ax.get_legend_handles_labels()[1])
        assert {"siren_torch", "interp"} <= labels
        if "SSIM" in ax.get_ylabel() or "PSNR" in ax.get_ylabel():
            assert "raw" in labels
        assert [t.get_text() for t in ax.get_xticklabels()] == ["2", "4", "8"]
    ssim_a = next(ax for ax in panels if ax.get_title() == "scene=a" and "SSIM" in ax.get_ylabel())
    siren = next(c.lines[0] for c in ssim_a.containers if c.get_label() == "siren_torch")
    np.testing.assert_allclose(np.asarray(siren.get_xdata(), float), [2, 4, 8])
    np.testing.assert_allclose(np.asarray(siren.get_ydata(), float),
                               [0.9 / s + 0.01 for s in (2, 4, 8)])
    assert "higher is better" in ssim_a.get_ylabel()


def test_markdown_table_holds_the_plotted_numbers():
    runs = sparsity_sweep(seeds=(1, 2))
    layout = sweep_layout(runs)
    text = quality_table(quality_points(runs, layout), layout)
    assert "| split.spatial_step | siren_torch | interp | raw |" in text
    assert f"| 2 | {0.9 / 2 + 0.015:.4g} ({0.9 / 2 + 0.01:.4g} to {0.9 / 2 + 0.02:.4g}) |" in text
