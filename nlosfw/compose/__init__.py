"""Composing a run's configuration with Hydra, and checking it before anything is written.

Used by the command line (:mod:`nlosfw.cli`) and by :func:`nlosfw.run`: the ConfigStore
entries of the run's schema and of every plugin (:mod:`~nlosfw.compose.store`), the
checks of every composition a command will run (:mod:`~nlosfw.compose.checks`), the
output directories (:mod:`~nlosfw.compose.output_dirs`), and one configuration run in
this process (:mod:`~nlosfw.compose.inprocess`).
"""

from nlosfw.compose.checks import composition_error, preflight, validate_config
from nlosfw.compose.inprocess import compose_run_config, plan_run, run_in_process
from nlosfw.compose.store import (
    RUN_SCHEMA,
    ensure_resolvers,
    hydra_session,
    normalise_overrides,
    register_configs,
)

__all__ = [
    "RUN_SCHEMA",
    "composition_error",
    "compose_run_config",
    "ensure_resolvers",
    "hydra_session",
    "normalise_overrides",
    "plan_run",
    "preflight",
    "register_configs",
    "run_in_process",
    "validate_config",
]
