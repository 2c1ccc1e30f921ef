"""Registration of the built-in plugins.

This module is the core distribution's ``nlosfw`` entry point: the built-ins
register through exactly the same hooks as third-party plugins.
"""

from __future__ import annotations

from typing import Any

from nlosfw.plugins.hookspecs import hookimpl


@hookimpl
def register_simulators(register: Any) -> None:
    from nlosfw.builtin.analytic import AnalyticConfig

    register(
        "analytic",
        "nlosfw.builtin.analytic:AnalyticSimulator",
        config=AnalyticConfig,
        description="Exact three-bounce transients of points and patches (no visibility)",
        test_config={"patch_size": 0.05},
    )
