"""The memory a neural field model holds while it trains, estimated from its options alone.

A neural model brings a runtime (PyTorch, JAX) whose import alone takes about 150-200 MB,
whose first training adds its own working memory (thread pools, allocator caches, JAX's
compiled programs), and which then holds, per run, the training samples in its own formats
and a batch's activations, gradients and Adam state. A model's estimate
(:meth:`~nlosfw.model.FieldModel.estimate_memory`) is arithmetic on its options and the
run's sizes (:class:`~nlosfw.common.memory.PlanShape`): nothing is allocated or imported.
For a model whose backend is B, with N = F·S·L training samples (F
frequencies, S sensor points, L laser points), a batch of b samples and hidden layers of
widths w₁ … wₖ (:meth:`~nlosfw.model.neural.NeuralFieldConfig.activation_widths`: a
Fourier-feature encoding's 2·``features`` outputs count as one more):

===================  =======================================================================
the runtime          IMPORT[B] when B is not imported yet (once it is, the program's
                     resident memory counts it) + WORKING[B] (its first training)
training data        PER_SAMPLE[B]·N (inputs, targets, the validation split, predictions)
training activations PER_ACTIVATION[B]·b·(w₁ + … + wₖ)
network parameters   PER_PARAMETER[B]·P, P the networks' parameters (one network in ``multi``
                     mode, one per frequency in ``single`` mode)
===================  =======================================================================

P is counted from the network's own description: the arrays its config's
:meth:`~nlosfw.model.neural.NeuralFieldConfig.network_shapes` lists for the field's shape
(layer widths, a hash grid's tables, ...). A model that trains a registered network of its
own (``rsd_residual_*``, ``neural_volume_*``) estimates it through the same function with
that network's config. Training holds
four float32 copies of every parameter (the weights, their gradients and Adam's two
moments: 16 bytes); the engines' initial weights (drawn in float64 by numpy, then
converted) and the best step's copy bring the peak to PER_PARAMETER, fitted to the peak
added by a fit of ``siren_<B>`` with hidden layers [3000, 3000] and [6000, 6000]
(9.0 and 36.0 million parameters: 390 and 1270 MB with torch, 388 and 1103 MB with jax,
slopes of 33 and 27 bytes per parameter).

The training history adds about 400 bytes per evaluation (``steps / eval_every``).

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

import math
import sys
from dataclasses import dataclass, replace

from nlosfw.common.errors import NlosfwError
from nlosfw.common.memory import MemoryEstimate, MemoryPart, PlanShape
from nlosfw.model.neural.config import FieldMode, FieldShape, NeuralFieldConfig

_MB = 1e6
#: Bytes one entry of a neural model's training history takes (a small dict of floats).
HISTORY_ENTRY = 400


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
    per_parameter: float
    """Per network parameter (weights, gradients, Adam's two moments, initial weights)."""


#: Measured figures per backend module (see the module's documentation for how).
BACKENDS: dict[str, BackendMemory] = {
    "torch": BackendMemory(imported=194 * _MB, working=46 * _MB, per_sample=147.0,
                           per_activation=58.0, per_parameter=36.0),
    "jax": BackendMemory(imported=148 * _MB, working=140 * _MB, per_sample=283.0,
                         per_activation=50.0, per_parameter=30.0),
}


def runtime_part(backend: str) -> MemoryPart:
    """The runtime of ``backend``: its import (unless this process has done it: then the
    program's resident memory counts it) and its first training; one per run, whichever
    models use it."""
    figures = BACKENDS[backend]
    imported = 0.0 if backend in sys.modules else figures.imported
    return MemoryPart("the model's runtime", f"{backend} and its first training",
                      figures.working + imported, once=f"runtime:{backend}")


def field_shape(shape: PlanShape, mode: FieldMode) -> FieldShape:
    """The shape of the field a network trains on in a run of ``shape``: the wall grid
    (for a list of points, the square grid of as many), every frequency."""
    return FieldShape(mode, shape.square_grid, shape.frequencies)


def parameter_count(config: NeuralFieldConfig, field: FieldShape) -> int | None:
    """The parameters of the networks ``config`` trains on a field of ``field``'s shape
    (one network per frequency in ``single`` mode); None when its description fails."""
    mode = FieldMode(config.mode)
    try:
        arrays = config.network_shapes(replace(field, mode=mode))
    except NlosfwError:
        return None
    networks = (field.n_frequencies or 1) if mode == FieldMode.single else 1
    return networks * sum(math.prod(size) for size in arrays.values())


def network_memory(config: NeuralFieldConfig, backend: str, field: FieldShape,
                   samples: float) -> MemoryEstimate:
    """What training a network of ``config`` on ``backend`` holds: the runtime, ``samples``
    training samples and a batch's activations, its parameters with their gradients and
    Adam's moments, the history. Empty for a backend without measured figures."""
    figures = BACKENDS.get(backend)
    if figures is None:
        return MemoryEstimate()
    batch = min(config.batch_size, int(samples)) if config.batch_size > 0 else int(samples)
    widths = config.activation_widths()
    parts = [runtime_part(backend),
             MemoryPart("the model's training", f"{samples:.0f} samples, batches of {batch} "
                        f"× {widths} hidden units",
                        figures.per_sample * samples + figures.per_activation * batch * widths)]
    count = parameter_count(config, field)
    if count:
        parts.append(MemoryPart("the networks' parameters", f"{count:,} parameters, each "
                                "with its gradient and Adam's two moments",
                                figures.per_parameter * count))
    evaluations = config.steps / max(config.eval_every, 1)
    parts.append(MemoryPart("the training history", f"{config.steps} steps / eval_every "
                            f"{config.eval_every}", evaluations * HISTORY_ENTRY))
    return MemoryEstimate(tuple(parts))
