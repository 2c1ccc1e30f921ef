"""Published numbers next to a run's own (``published`` tables), and the old names of count
splitting's and the thesis's options refused in one line naming the new ones."""

from __future__ import annotations

import pytest

from nlosfw.cli import main
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.pipeline.metrics import (
    FieldMetrics,
    FitMetrics,
    RunInfo,
    RunMetrics,
    metrics_schema_text,
)
from nlosfw.pipeline.settings import PublishedTable, run_settings
from nlosfw.report.published_numbers import published_comparison
from nlosfw.report.records import RunRecord, read_run

QUICK = ["scene=tiny", "model=interp", "imager=fft", "figures.enabled=false",
         "transform.n_frequencies=11", "reconstruction.n_depths=4"]

TABLE = {"title": "A paper, Table 2", "note": "Read\n  me.",
         "rows": {"interp": {"label": "the baseline", "n_parameters": 5,
                             "fit": {"steps": 1, "final_loss": 0.5}}}}


def _metrics(n_parameters: int | None) -> RunMetrics:
    info = RunInfo(dir="d", nlosfw_version="0", started="s", config_hash="h", scene="tiny",
                   simulator="analytic", transform="fft", model="interp", imager="fft")
    fit = FitMetrics(steps=1, seconds=0.1, final_loss=0.25, best_val_loss=None,
                     stopped_early=False)
    field = None if n_parameters is None else {"interp": FieldMetrics(
        plugin="interp", n_parameters=n_parameters, training_values=10,
        parameters_per_value=n_parameters / 10, fit=fit)}
    return RunMetrics(run=info, field=field)


@pytest.mark.parametrize(("override", "line"), [
    ("split.thinning=true",
     "error: split.thinning: was renamed; write split.count_splitting instead"),
    ("+split.thinning_seed=3",
     "error: split.thinning_seed: was renamed; write split.count_splitting_seed instead"),
    ('+thesis={figure: "5.4"}', "error: thesis: was renamed; write published instead"),
])
def test_an_old_name_is_refused_in_one_line_before_the_run(tmp_path, monkeypatch, capsys,
                                                           override, line):
    monkeypatch.chdir(tmp_path)
    status = main([*QUICK, override, f"hydra.run.dir={tmp_path / 'run'}"])
    assert status == 2 and capsys.readouterr().err == line + "\n"
    assert not (tmp_path / "run").exists()


def test_the_old_names_are_refused_from_python_too():
    for options, option in (({"split": {"thinning": True}}, "split.thinning"),
                            ({"thesis": {"figure": "5.4"}}, "thesis")):
        with pytest.raises(ConfigError) as err:
            run_settings(options)
        assert err.value.option == option and "was renamed" in err.value.problem


@pytest.mark.parametrize(("table", "option", "problem"), [
    ({"rows": {"interp": {"fit": {"final_los": 1.0}}}}, "published.t.rows.interp.fit.final_los",
     "names no number of metrics.json's field.<source>; valid: seed, n_parameters"),
    ({"rows": {"interp": {"n_parameters": "many"}}}, "published.t.rows.interp.n_parameters",
     "must be a number, got 'many'"),
    ({"rows": {"pe": {"n_parameters": 3}}}, "published.t.rows.pe",
     "names no field model of the run; valid: interp, model"),
    ({"titel": "x"}, "published.t.titel", "unknown option; valid options: note, rows, title"),
])
def test_a_malformed_table_names_its_option(table, option, problem):
    with pytest.raises(ConfigError) as err:
        run_settings({"published": {"t": table}})
    assert err.value.option == option and err.value.problem.startswith(problem)


def test_a_run_writes_its_numbers_next_to_the_published_ones(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("NLOSFW_CACHE_DIR", str(tmp_path / "cache"))
    table = ('++published={t: {title: "A paper, Table 2", note: "Read me.", rows: {interp: '
             '{label: "the baseline", n_parameters: 5, fit: {steps: 1, final_loss: 0.5}}}}}')
    run = tmp_path / "run"
    assert main([*QUICK, table, f"hydra.run.dir={run}"]) == 0
    text = (run / "published_numbers.md").read_text()
    record = read_run(run, tmp_path)
    ours = record.metrics.field_entry("interp")
    assert ours is not None
    assert text.splitlines()[:3] == [
        "### A paper, Table 2", "",
        "| row | n_parameters (ours) | n_parameters (published) | fit.steps (ours) | "
        "fit.steps (published) | fit.final_loss (ours) | fit.final_loss (published) | run |"]
    assert f"| the baseline | {ours.n_parameters} | 5 | {ours.fit.steps} | 1 | " in text
    assert text.endswith("| run |\n\nRead me.\n")
    assert record.published["t"].rows["interp"]["n_parameters"] == 5


def test_one_table_gathers_every_run_naming_it():
    table = PublishedTable(**TABLE)
    records = [RunRecord(name="a", metrics=_metrics(7), published={"t": table}),
               RunRecord(name="b", metrics=_metrics(None), published={"t": table}),
               RunRecord(name="c", metrics=_metrics(9))]
    text = published_comparison(records)
    assert text.count("### A paper, Table 2") == 1
    assert "| the baseline | 7 | 5 | 1 | 1 | 0.25 | 0.5 | a |" in text
    assert "| the baseline | - | 5 | - | 1 | - | 0.5 | b |" in text   # no entry: no number
    assert "| c |" not in text and text.endswith("\nRead me.\n")
    assert published_comparison(records[2:]) == ""


def test_a_runs_malformed_table_is_a_data_error_naming_its_config(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.json").write_text(_metrics(7).dumps())
    (run / "metrics.schema.json").write_text(metrics_schema_text())
    (run / "config.yaml").write_text("published: {t: {rows: {interp: {n_parameters: x}}}}\n")
    with pytest.raises(DataError) as err:
        read_run(run, tmp_path)
    assert str(err.value).startswith(f"{run / 'config.yaml'}: published.t.rows.interp")


def test_the_old_report_name_still_loads_with_a_warning():
    import nlosfw.report

    with pytest.warns(DeprecationWarning, match="nlosfw.report.published_comparison"):
        assert nlosfw.report.thesis_comparison is published_comparison
