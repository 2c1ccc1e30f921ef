"""The job numbering a resumed sweep is checked against is Hydra's own."""

from __future__ import annotations

import pytest
from hydra.core.override_parser.overrides_parser import OverridesParser

from nlosfw.common.errors import ConfigError
from nlosfw.compose.output_dirs import sweep_jobs


@pytest.mark.parametrize("arguments", [
    ["model=a,b", "scene=x"],
    ["scene=x,y,z", "split.spatial_step=2,4,8", "model.seed=0,1,2", "scene=letter_t,tiny"],
    ["+compare.pe.name=pe_torch", "model=interp", "transform.n_frequencies=21,31"],
])
def test_jobs_are_numbered_as_hydras_basic_sweeper_numbers_them(arguments):
    # Hydra's private sweeper is the reference here only; nlosfw itself uses public API
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    parsed = OverridesParser.create().parse_overrides(arguments)
    (reference,) = BasicSweeper.split_arguments(parsed, None)
    assert sweep_jobs(parsed) == reference
    assert len(sweep_jobs(parsed)) == len(reference) > 1


def test_a_range_sweep_is_refused_in_one_line():
    parsed = OverridesParser.create().parse_overrides(["model.lr=interval(0.001,0.1)"])
    with pytest.raises(ConfigError, match="model.lr: only comma-separated"):
        sweep_jobs(parsed)
