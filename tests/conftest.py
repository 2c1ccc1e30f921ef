"""Checks every test gets: each metrics.json a run wrote in the test's tmp_path matches the
JSON Schema written beside it and reads back as the same :class:`RunMetrics`.

A test that plants a malformed metrics.json on purpose is marked ``malformed_metrics``.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

#: JAX's persistent compilation cache for the session: every model a test builds traces
#: new functions, but most compile to programs the suite compiled before (the same network
#: and shapes, another seed), and the cache reuses them (the JAX conformance checks of one
#: network: 52 s without it, 27 s with it). Every program is cached, however quick to build.
JAX_CACHE_SETTINGS = {"JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
                      "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0"}


def share_jax_compilation_cache(config: pytest.Config) -> None:
    """Point JAX (in this process, the pytest-xdist workers and the runs the tests start,
    through the environment they inherit) at one cache folder for the session, removed at
    its end; a cache folder already set (a worker's, or the user's own) is kept."""
    if "JAX_COMPILATION_CACHE_DIR" in os.environ:
        return
    path = tempfile.mkdtemp(prefix="nlosfw-tests-jax-cache-")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = path
    for name, value in JAX_CACHE_SETTINGS.items():
        os.environ.setdefault(name, value)
    config.add_cleanup(lambda: shutil.rmtree(path, ignore_errors=True))


def pytest_configure(config: pytest.Config) -> None:
    """The session's JAX compilation cache (:func:`share_jax_compilation_cache`).

    absl (imported with JAX) logs through a handler bound to the ``sys.stderr`` of the
    moment it is imported: under pytest, a capture buffer. An in-process run configures
    Hydra's logging, which closes every handler, and absl's handler closes its stream, so
    the session's capture breaks ("I/O operation on closed file" at the end of the
    session). Bind absl's handler to the process's own stderr, which it never closes."""
    share_jax_compilation_cache(config)
    try:
        from absl import logging as absl_logging
    except ImportError:
        return
    absl_logging.get_absl_handler().python_handler.stream = sys.__stderr__


def check_metrics_file(path: Path) -> None:
    """``path`` (a metrics.json) validates against ``metrics.schema.json`` beside it, and
    :class:`RunMetrics` reads it back unchanged."""
    import jsonschema

    from nlosfw.pipeline.metrics import RunMetrics

    schema_path = path.with_name("metrics.schema.json")
    assert schema_path.is_file(), f"{path}: no metrics.schema.json beside it"
    schema = json.loads(schema_path.read_text())
    data = json.loads(path.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}"
              for e in jsonschema.Draft202012Validator(schema).iter_errors(data)]
    assert not errors, f"{path} does not match its schema: {errors}"
    assert RunMetrics.from_json(data, where=str(path)).to_json() == data


@pytest.fixture(autouse=True)
def _metrics_files_match_their_schema(request: pytest.FixtureRequest):
    if "tmp_path" not in request.fixturenames or request.node.get_closest_marker(
            "malformed_metrics"):
        yield
        return
    root: Path = request.getfixturevalue("tmp_path")
    yield
    for path in sorted(root.rglob("metrics.json")):
        check_metrics_file(path)
