"""The thesis experiment presets and sweeps, run at reduced size (full size: see README)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from nlosfw.common import yaml_safe
from nlosfw.model.neural.catalogue import PRESETS
from nlosfw.model.neural.mlp import FAMILY_CONFIGS, count_parameters, resolve_architecture

CONF = Path(__file__).resolve().parents[2] / "conf"

#: Shrinks any preset: a 16x16 wall, few frequencies, a few training steps, few depths.
SMALL = ["scene.wall.resolution=[16,16]", "transform.n_frequencies=21", "model.steps=30",
         "model.eval_every=10", "reconstruction.n_depths=6", "figures.enabled=false"]
EXTRA = {
    "thesis_fig4_3": ["model.batch_size=256"],
    **{f"thesis_fig5_{k}": ["simulator.samples=2048"] for k in (1, 3, 4, 5)},
}
PRESET_NAMES = sorted(p.stem for p in (CONF / "experiment").glob("thesis_fig*.yaml"))


def nlosfw(*args, cwd):
    env = {**os.environ, "COLUMNS": "200", "NLOSFW_CACHE_DIR": str(Path(cwd) / "cache")}
    result = subprocess.run([sys.executable, "-m", "nlosfw", *args], cwd=cwd, env=env,
                            capture_output=True, text=True, timeout=900, check=False)
    assert result.returncode == 0, f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}"
    return result


def preset(name):
    return yaml_safe.load((CONF / "experiment" / f"{name}.yaml").read_text())


def published_rows(cfg: dict) -> dict:
    """The rows of every reference table of a preset's config, by source."""
    return {source: row for table in cfg["published"].values()
            for source, row in table["rows"].items()}


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_preset_architectures_match_the_thesis_parameter_counts(name):
    """Each preset's networks have exactly the parameters the thesis lists for them."""
    cfg = preset(name)
    rows = published_rows(cfg)
    models = {"model": cfg["model"], **cfg.get("compare", {})}
    families = {"tanh_torch": "tanh", "pe_torch": "pe", "siren_torch": "siren"}
    model_name = cfg["defaults"][-1]["override /model"]
    for source, options in models.items():
        plugin = options.get("name", model_name)
        family = families[plugin]
        arch_keys = {"mode", "hidden", "octaves", "include_input", "frequency_input",
                     "activation", "omega0_first", "omega0_hidden"}
        arch_options = {k: v for k, v in options.items() if k in arch_keys}
        config = FAMILY_CONFIGS[family](**{k: tuple(v) if isinstance(v, list) else v
                                           for k, v in arch_options.items()})
        n_freq = 1 if config.mode == "single" else 135
        arch = resolve_architecture(family, config, (32, 32), n_freq)
        per_network = count_parameters(arch)
        expected = rows[source].get("n_parameters") or PRESETS["thesis_siren"].parameters
        assert per_network == expected, (name, source, per_network, expected)


@pytest.mark.slow
@pytest.mark.parametrize("name", PRESET_NAMES)
def test_every_preset_runs_at_reduced_size(tmp_path, name):
    nlosfw(f"experiment={name}", *SMALL, *EXTRA.get(name, []), cwd=tmp_path)
    (run,) = list((tmp_path / "outputs").glob("*/*"))
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["status"] == "completed"
    cfg = preset(name)
    for source in published_rows(cfg):
        assert metrics["field"][source]["splits"]["all"]["nmse_db"] is not None
    table = (run / "published_numbers.md").read_text()
    assert "### Thesis, Table" in table and "(published)" in table
    assert "| " + run.name in table


@pytest.mark.slow
def test_noise_study_reports_denoising(tmp_path):
    sweep = tmp_path / "noise"
    small = [a for a in SMALL if not a.startswith("model.")]
    nlosfw("-m", "experiment=noise_study", "scene.noise.photons=1e4,1e8", *small,
           "model=interp", f"hydra.sweep.dir={sweep}", cwd=tmp_path)
    results = {}
    for metrics_file in sweep.rglob("metrics.json"):
        metrics = json.loads(metrics_file.read_text())
        photons = metrics["capture"]["noise"]["photons"]
        results[photons] = metrics["field"]["interp"]["denoising"]
    assert set(results) == {1e4, 1e8}
    # more photons, less noise in the measured field
    assert results[1e4]["noisy_relative_l2"] > 5 * results[1e8]["noisy_relative_l2"]
    # 1e8 photons is nearly noise-free; 1e4 is dominated by shot noise (relative error of
    # a Poisson count N is 1/sqrt(N): the brightest bins hold far fewer than 1e4 photons)
    assert results[1e8]["noisy_relative_l2"] < 0.05
    assert results[1e4]["noisy_relative_l2"] > 0.3
    # more noise in the samples cannot bring the prediction closer to the clean field
    assert results[1e4]["relative_l2"] > results[1e8]["relative_l2"]


@pytest.mark.slow
def test_table_4_1_sweep_and_report_next_to_the_thesis(tmp_path):
    sweep = tmp_path / "table"
    nlosfw("-cn", "thesis_table4_1", "-m", *SMALL, "model.batch_size=256",
           f"hydra.sweep.dir={sweep}", cwd=tmp_path)
    assert len(list(sweep.rglob("metrics.json"))) == 3
    nlosfw("report", str(sweep), cwd=tmp_path)
    report = (sweep / "report" / "report.md").read_text()
    assert "### Thesis, Table 4.1: parameters and compression" in report
    for row in ("Mono frequency + upsampling (MLP)", "Multi frequency (MLP + PE)",
                "Multi frequency + upsampling (MLP + Sin)"):
        assert row in report
    # our counts are exact: the thesis architectures
    assert "| 942 | 942 |" in report and "| 3362 | 3362 |" in report
