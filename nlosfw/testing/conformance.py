"""Every planned conformance check as a pytest test, for ``python -m nlosfw.testing``.

``pytest --pyargs nlosfw.testing.conformance`` runs the checks of every installed
plugin; ``python -m nlosfw.testing NAME`` runs those of one plugin (it puts the
selected names in :data:`SELECTED`).
"""

from __future__ import annotations

import pytest

from nlosfw.plugins.registry import PluginSpec
from nlosfw.testing.kit import check_cases, pytest_params
from nlosfw.testing.selection import PlannedCheck

#: Where ``python -m nlosfw.testing`` stores the plugin names to check (all when absent).
SELECTED = pytest.StashKey[tuple[str, ...]]()


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """Parametrize ``test_conformance`` over the planned (plugin, check) pairs."""
    if {"spec", "check"} <= set(metafunc.fixturenames):
        names = metafunc.config.stash.get(SELECTED, None)
        metafunc.parametrize("spec, check", pytest_params(check_cases(names=names)))


def test_conformance(spec: PluginSpec, check: PlannedCheck) -> None:
    check(spec)
