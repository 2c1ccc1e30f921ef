"""The memory a neural field model holds while it trains, estimated without importing it.

A neural model brings a runtime (PyTorch, JAX) whose import alone takes about 150-200 MB,
whose first training adds its own working memory (thread pools, allocator caches, JAX's
compiled programs), and which then holds, per run, the training samples in its own formats
and a batch's activations, gradients and Adam state. The backend of a model is read from
what its plugin declares it needs (``requires``: ``torch``, ``jax``), so nothing is imported
to estimate it. For a model whose backend is B, with N = F·S·L training samples (F
frequencies, S sensor points, L laser points), a batch of b samples and hidden layers of
widths w₁ … wₖ (``hidden``, or ``network_hidden`` for a residual network; a Fourier-feature
encoding's 2·``features`` outputs count as one more):

===================  =======================================================================
the runtime          IMPORT[B] when B is not imported yet (once it is, the program's
                     resident memory counts it) + WORKING[B] (its first training)
training data        PER_SAMPLE[B]·N (inputs, targets, the validation split, predictions)
training activations PER_ACTIVATION[B]·b·(w₁ + … + wₖ)
===================  =======================================================================

The figures (:data:`BACKENDS`) were measured on the project's CPU machine (x86_64, torch
2.13.0 CPU, jax 0.10.2 CPU, float32) with ``resource.getrusage(RUSAGE_SELF).ru_maxrss`` and
``/proc/self/statm`` around ``nlosfw.api.fit_model(smooth_field(n, F), "siren_<B>",
steps=100, ...)`` in a fresh process: IMPORT is the resident memory added by loading the
model's plugin (``spec.load()``: the engine and the backend); the rest was fitted to the peak
added by the fit over 32 × 32 and 64 × 64 fields of 16 and 151 frequencies, batches of 2048
and 8192 samples and hidden layers [64, 64, 64] and [256, 256, 256] (each figure within
0.8-1.2 of the measured peak). Peaks measured, MB above the imported backend:

========================================  ========  =======
field, batch, hidden                      torch     jax
========================================  ========  =======
32 × 32 × 16, 8192, [64, 64, 64]          173       242
32 × 32 × 151, 8192, [64, 64, 64]         160       263
64 × 64 × 151, 8192, [64, 64, 64]         228       394
64 × 64 × 151, 2048, [64, 64, 64]         192       344
64 × 64 × 151, 8192, [256, 256, 256]      502       644
========================================  ========  =======
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from nlosfw.plugins.kinds import PluginKind

if TYPE_CHECKING:
    from nlosfw.plugins import PluginHost

#: The modules a field model named so needs (as its plugin declares them), or () when unknown.
ModelRequires = Callable[[str], Iterable[str]]

_MB = 1e6


@dataclass(frozen=True)
class BackendMemory:
    """What a neural-network backend holds while a model trains on it (bytes)."""

    imported: float
    """Resident memory added by importing it (and the model's engine)."""
    working: float
    """Added by its first training, whatever its size (threads, caches, compiled code)."""
    per_sample: float
    """Per training sample (inputs, targets, the validation split, predictions)."""
    per_activation: float
    """Per batch sample per hidden unit (activations, their gradients, optimiser buffers)."""


#: Measured figures per backend module (see the module's documentation for how).
BACKENDS: dict[str, BackendMemory] = {
    "torch": BackendMemory(imported=194 * _MB, working=46 * _MB, per_sample=147.0,
                           per_activation=58.0),
    "jax": BackendMemory(imported=148 * _MB, working=140 * _MB, per_sample=283.0,
                         per_activation=50.0),
}


def backend_of(modules: Iterable[str]) -> str | None:
    """The backend of :data:`BACKENDS` among the modules a model needs, or None."""
    needed = set(modules)
    return next((name for name in BACKENDS if name in needed), None)


def imported(module: str) -> bool:
    """Whether ``module`` is imported in this process already (nothing is imported)."""
    return module in sys.modules


def plugin_requires(host: PluginHost) -> ModelRequires:
    """The :data:`ModelRequires` of the field models ``host`` registers (from their
    declared requirements; no plugin is imported)."""

    def requires(name: str) -> Iterable[str]:
        if name not in host.registry.names(PluginKind.FIELD_MODEL):
            return ()
        spec = host.registry.get(PluginKind.FIELD_MODEL, name)
        return tuple(module for module, _ in spec.requires)

    return requires


def _int(value: object, default: int) -> int:
    try:
        return int(value)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        return default


def training_bytes(options: Mapping[str, object], backend: str, samples: float
                   ) -> tuple[float, float]:
    """(data, activations): the bytes a model of ``options`` on ``backend`` holds while
    training on ``samples`` samples (see the module's table)."""
    figures = BACKENDS[backend]
    hidden = options.get("hidden", options.get("network_hidden")) or ()
    widths = sum(_int(w, 0) for w in hidden) if isinstance(hidden, Iterable) else 0
    widths += 2 * max(0, _int(options.get("features"), 0))
    batch = _int(options.get("batch_size", options.get("network_batch_size")), 0)
    batch = min(batch, int(samples)) if batch > 0 else int(samples)
    return figures.per_sample * samples, figures.per_activation * batch * widths


def runtime_bytes(backends: Iterable[str]) -> float:
    """The runtimes of ``backends`` (each counted once): import (unless done) + working."""
    return sum(BACKENDS[b].working + (0.0 if imported(b) else BACKENDS[b].imported)
               for b in set(backends))
