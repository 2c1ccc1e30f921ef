"""The ``rsd_prior`` field model: the wall field of a non-negative hidden albedo.

Instead of a generic function of (x, y, f), the field is explained by a hidden scene: a
non-negative albedo a on voxel planes parallel to the wall, the same at every frequency,
propagated to the wall by the physics of :mod:`nlosfw.model.physics.operator` (laser spot
-> voxel -> wall, or the doubled path of confocal scans). Fitting solves

    min_{a >= 0}  1/2 sum_f ||A_f a - P_f||^2 + l1 sum_v n_v a_v + tv TV(n a)

over the sparse wall samples P_f (``fit_frequencies`` of the field's frequencies, evenly
spread), n_v = ||A e_v|| being the column norms: FISTA (monotone,
:mod:`nlosfw.model.physics.solver`) runs on x = n a, so every column has unit norm (much
faster convergence) and a weak, distant voxel pays the same L1 price as a bright near one
for the same contribution to the data. The step is 1/L from a power iteration. The weights
are relative: l1 = ``l1_weight`` * max Re(A_n^H P), the smallest weight at which the
solution is zero (A_n the normalised operator); TV is a smoothed total variation of x
within each plane (off by default).
The fitted albedo then predicts the field anywhere on the wall and at any frequency: on
a regular grid whose spacing and the voxels' are whole multiples of one another by FFT
convolution, elsewhere by a direct sum over the non-zero voxels.

Voxels: planes ``depth.step`` apart (default a fifth of the shortest wavelength; the
feasibility study found about 1.3 cm necessary, 3.9 cm stalls) over ``depth.range``, or
chosen from the data (below), on a lateral lattice of spacing ``lateral_step`` (default
half the shortest wavelength, a quarter for confocal scans, rounded down so that the
training spacing is a whole multiple of it) covering the training grid and half a
training spacing beyond. Enough frequencies are fitted that paths over twice the depth
span do not alias in time.

A random scan (scattered samples) is fitted on the grid its points came from
(:func:`~nlosfw.model.physics.wall.wall_samples`), the operator masked to the kept points.

Automatic depth planes: a quick coarse fit finds where the scene is
(:mod:`nlosfw.model.physics.lattice`).

Terms of real systems, each fitted jointly and reported in the fit report: ``background:
constant``, a complex offset per frequency, constant over the wall (minimised out exactly:
:mod:`nlosfw.model.physics.background`); ``response.temporal: gaussian`` and
``response.time_offset``, a gain per frequency (jitter, a time-origin offset in ps;
:mod:`nlosfw.model.physics.response`); ``lobe.fit``, a glossy lobe's exponent
(:mod:`nlosfw.model.physics.lobe`; or a fixed ``lobe.exponent``).
``likelihood: poisson`` weighs each wall point by the inverse Poisson variance of its
samples (:mod:`nlosfw.model.physics.likelihood`); ``likelihood: poisson_counts`` refines the
albedo by the exact Poisson likelihood of the photon counts in every time bin, with a
background per bin (:mod:`nlosfw.model.physics.counts`).

The field's device legs (when its time axis has them) are taken out before the fit and
put back in predictions. The model is the simulators' own physics (an inverse crime on
simulated captures): judge it on noisy, occluded and mis-calibrated captures.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from nlosfw.capture.geometry import CaptureGeometry
from nlosfw.common.errors import ConfigError, DataError, FitError
from nlosfw.image.fft import Precision
from nlosfw.image.plane_convolution import GridLayout, from_canonical, grid_layout
from nlosfw.image.rsd_kernel import check_geometry
from nlosfw.model.interface import (
    FieldModel,
    FitReport,
    TrainingStep,
    check_query,
    check_training_field,
)
from nlosfw.model.model_files import read_model_file, stored_config, write_model_file
from nlosfw.model.physics.background import (
    BackgroundProjection,
    WallBackground,
    background_projection,
    fit_offsets,
)
from nlosfw.model.physics.config import RSDPriorConfig
from nlosfw.model.physics.counts import CountsScene, refine_by_counts
from nlosfw.model.physics.lattice import plan_lattice
from nlosfw.model.physics.likelihood import Likelihood, sample_weights, weight_summary
from nlosfw.model.physics.lobe import fit_lobe
from nlosfw.model.physics.operator import (
    OperatorOptions,
    SceneOperator,
    VoxelLattice,
    direct_fields,
)
from nlosfw.model.physics.response import (
    SystemResponse,
    TemporalResponse,
    estimate_response,
    search_response,
    with_gains,
)
from nlosfw.model.physics.solver import FistaProblem, FistaResult, lipschitz, solve, tv_lipschitz
from nlosfw.model.physics.wall import WallSamples, training_values
from nlosfw.transform.field import PhasorField
from nlosfw.transform.temporal_dft import unit_phasor

log = logging.getLogger(__name__)

#: Model name written in saved files.
MODEL_NAME = "rsd_prior"
#: Frequencies propagated at once when predicting (bounds memory).
_PREDICT_CHUNK = 16
#: Smoothing of the total variation, relative to the albedo's typical value.
_TV_EPS = 0.1


@dataclass(frozen=True, eq=False)
class _Fitted:
    """What a fit leaves: the lattice, the albedo on it, and how to put the field back."""

    lattice: VoxelLattice
    albedo: np.ndarray
    geometry: CaptureGeometry
    scale: float
    background: WallBackground | None = None
    response: SystemResponse | None = None
    lobe: float = 0.0


class RSDPriorFieldModel(FieldModel[RSDPriorConfig]):
    """The wall field of a fitted non-negative voxel albedo (see the module docstring)."""

    config_class = RSDPriorConfig
    family = MODEL_NAME

    def __init__(self, config: RSDPriorConfig | Mapping[str, object] | None = None) -> None:
        super().__init__(config)
        self._fitted: _Fitted | None = None
        self._projection: BackgroundProjection | None = None
        self._weights: np.ndarray | None = None       # sqrt of the likelihood's weights

    # ------------------------------------------------------------------ fit
    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable[[TrainingStep], None] | None = None) -> FitReport:
        """Fit the albedo to ``field`` (``validation`` is unused)."""
        start = time.perf_counter()
        cfg = self.config
        check_training_field(field, MODEL_NAME)
        check_geometry(field.geometry)
        samples, values, scale = training_values(field)
        wall, mask = samples.layout, samples.mask
        self._projection = background_projection(cfg.background, field, samples)
        poisson = cfg.likelihood == Likelihood.poisson
        self._weights = sample_weights(field, samples) if poisson else None
        lattice, chosen = self.plan_lattice(values, samples, field)
        depths, freqs = lattice.depths, field.frequencies[chosen]
        def operator(k: float, f: np.ndarray = freqs) -> SceneOperator:
            return SceneOperator(lattice, wall, field.geometry, f, self._options(lobe=k), mask)

        lobe = (self.search_lobe(field, values, samples, lattice, chosen) if cfg.lobe.fit
                else cfg.lobe.exponent)
        log.info("rsd_prior: %d planes in %.3f-%.3f m, %d x %d voxels, %d frequencies",
                 depths.size, depths.min(), depths.max(), *lattice.shape, freqs.size)
        history: list[dict[str, float]] = []

        def report(k: int, objective: float, residual: float) -> None:
            if k == 1 or k % 10 == 0 or k == cfg.iterations:
                history.append({"step": k, "objective": objective, "relative_residual": residual})
            if on_step is not None:
                on_step(TrainingStep(step=k, total_steps=cfg.iterations, loss=residual,
                                     seconds=time.perf_counter() - start))

        albedo, response, result = self._fit_albedo(operator(lobe), values[chosen], report)
        background = None if self._projection is None else fit_offsets(
            self._projection,
            lambda f: with_gains(response, f, operator(lobe, f).forward(albedo)),
            field.frequencies, values, scale)
        counts = None
        if cfg.likelihood == Likelihood.poisson_counts:
            scene = CountsScene(lattice, field.geometry, self._options(lobe=lobe), response,
                                scale)
            counts = refine_by_counts(field, scene, albedo, cfg)
            albedo, background = counts.albedo, counts.background
        self._fitted = _Fitted(lattice, albedo.astype(np.float32), field.geometry, scale,
                               background, response, lobe)
        fitted = {**({} if background is None else background.summary(scale)),
                  **({} if response is None else response.summary()),
                  **({"lobe_exponent": lobe} if cfg.lobe.fit else {}),
                  **({} if self._weights is None else weight_summary(self._weights, mask)),
                  **({} if counts is None else counts.summary)}
        return FitReport(steps=result.iterations, seconds=time.perf_counter() - start,
                         final_loss=result.residual, fitted=fitted, history=history,
                         stopped_early=result.iterations < cfg.iterations)

    def _fit_albedo(self, op: SceneOperator, data: np.ndarray,
                    report: Callable[[int, float, float], None]
                    ) -> tuple[np.ndarray, SystemResponse | None, FistaResult]:
        """The albedo, and the system response when a term of it is on: least squares with
        the albedo fixed to start, then a search on the residual of albedos fitted again
        (``iterations`` / 4 from the best so far; :func:`search_response`)."""
        cfg = self.config
        gaussian = cfg.response.temporal == TemporalResponse.gaussian
        if not (gaussian or cfg.response.time_offset):
            albedo, result = self._solve(op, data, cfg.iterations, report)
            return albedo, None, result
        project = self._projector(op.frequencies)
        albedo, _ = self._solve(op, data, cfg.iterations)
        start = estimate_response(project(op.forward(albedo)), project(data), op.frequencies,
                                  gaussian, cfg.response.time_offset)
        best_value, best_albedo = math.inf, albedo     # the lowest residual so far

        def residual(response: SystemResponse) -> float:
            nonlocal best_value, best_albedo
            fitted, result = self._solve(op, data, max(1, cfg.iterations // 4), None,
                                         response.gains(op.frequencies, True), best_albedo)
            value = result.objective[-1]
            if value < best_value:
                best_value, best_albedo = value, fitted
            log.debug("rsd_prior: response %s: objective %.6g, residual %.5f",
                      response.summary(), value, result.residual)
            return value

        response = search_response(residual, start, float(np.abs(op.frequencies).max()),
                                   cfg.response.rounds)
        log.info("rsd_prior: system response %s", response.summary())
        albedo, result = self._solve(op, data, cfg.iterations, report,
                                     response.gains(op.frequencies, True), best_albedo)
        rms = float(np.sqrt(np.mean(np.abs(response.gains(op.frequencies)) ** 2)))
        return albedo / rms, response, result    # for the gains as they are, not unit RMS

    def _projector(self, frequencies: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        proj = self._projection
        return (lambda p: p) if proj is None else proj.projector(frequencies)

    def _solve(self, op: SceneOperator, data: np.ndarray, iterations: int,
               report: Callable[[int, float, float], None] | None = None,
               gains: np.ndarray | None = None, start: np.ndarray | None = None
               ) -> tuple[np.ndarray, FistaResult]:
        """The albedo fitted to ``data`` by FISTA on the column-normalised operator (times
        the per-frequency ``gains`` of the system response, if any; each wall point's
        residual weighted by the likelihood), from ``start``."""
        cfg = self.config
        weights = self._weights
        w = None if weights is None else weights.astype(data.real.dtype)
        norms = op.column_norms(None if weights is None else weights**2)
        project = self._projector(op.frequencies)
        data = project(data) if w is None else w * project(data)
        g = None if gains is None else gains.astype(data.dtype)[:, None, None]

        def forward(x: np.ndarray) -> np.ndarray:
            y = op.forward(x / norms)
            y = project(y if g is None else g * y)
            return y if w is None else w * y

        def adjoint(p: np.ndarray) -> np.ndarray:
            q = project(p if w is None else w * p)
            return op.adjoint(q if g is None else np.conj(g) * q) / norms

        shape = op.lattice.volume_shape
        lip = lipschitz(forward, adjoint, shape, cfg.power_iterations, cfg.seed)
        peak = float(adjoint(data).real.max())
        if not peak > 0 or not lip > 0:
            raise FitError(f"{MODEL_NAME}: no non-negative albedo correlates with the field "
                           "(max Re(A^H P) <= 0); check the capture geometry and the field's sign")
        tv = cfg.tv_weight * peak
        eps = _TV_EPS * peak / lip
        smooth_l = lip + (tv * tv_lipschitz(2, eps) if tv > 0 else 0.0)
        problem = FistaProblem(forward, adjoint, data, shape, l1=cfg.l1_weight * peak, tv=tv,
                               tv_eps=eps, tv_axes=(1, 2))
        result = solve(problem, cfg.step / smooth_l, iterations, report, cfg.tolerance,
                       None if start is None else start * norms)
        return result.x / norms, result

    def plan_lattice(self, values: np.ndarray, samples: WallSamples, field: PhasorField
                     ) -> tuple[VoxelLattice, np.ndarray]:
        """The voxel lattice a fit of ``field`` uses and the indices of the frequencies it
        fits (:func:`~nlosfw.model.physics.lattice.plan_lattice`); ``values``: the field without
        device legs on the wall grid of ``samples``, divided by its RMS."""
        return plan_lattice(self.config, values, samples, field, self._options(),
                            lambda op, data, n: self._solve(op, data, n)[0])

    def search_lobe(self, field: PhasorField, values: np.ndarray, samples: WallSamples,
                    lattice: VoxelLattice, chosen: np.ndarray) -> float:
        """The lobe exponent k fitted on the kept samples (``lobe.fit``'s held-out search,
        :func:`~nlosfw.model.physics.lobe.fit_lobe`) on ``lattice`` at the frequencies
        ``chosen``; arguments as for :meth:`plan_lattice`."""
        freqs = field.frequencies[chosen]

        def operator(k: float, keep: np.ndarray | None) -> SceneOperator:
            return SceneOperator(lattice, samples.layout, field.geometry, freqs,
                                 self._options(lobe=k), keep)

        return fit_lobe(self.config, operator, lambda op, d, n: self._solve(op, d, n)[0],
                        values[chosen], samples.mask)

    def _options(self, cache: bool = True, lobe: float | None = None) -> OperatorOptions:
        cfg = self.config
        dtype = np.complex64 if cfg.precision == Precision.single else np.complex128
        return OperatorOptions(amplitude=cfg.amplitude, dtype=dtype, workers=cfg.workers,
                               cache_mb=cfg.cache_mb if cache else 0.0,
                               lobe=cfg.lobe.exponent if lobe is None else lobe)

    # ------------------------------------------------------------------ predict
    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """The fitted scene's field at wall points (..., 2) and frequencies (F,) -> (F, ...)."""
        xy, f = check_query(wall_xy, frequencies, MODEL_NAME)
        fitted = self._stored()
        kept = np.flatnonzero(np.any(fitted.albedo != 0, axis=(1, 2)))
        lattice = replace(fitted.lattice, depths=fitted.lattice.depths[kept])
        albedo = fitted.albedo[kept]
        options = self._options(cache=False, lobe=fitted.lobe)
        layout = grid_layout(xy) if xy.ndim == 3 else None
        out: np.ndarray | None = None
        if layout is not None and kept.size:
            try:
                out = self._predict_grid(lattice, albedo, layout, f, options)
            except DataError:            # spacings not commensurate: sum directly
                out = None
        if out is None:
            points = xy.reshape(-1, 2)
            out = direct_fields(lattice, albedo, points, fitted.geometry, f, options)
        out = with_gains(fitted.response, f, out.reshape((f.size,) + xy.shape[:-1]).astype(
            np.complex128) * fitted.scale)
        if fitted.geometry.t_accounts_first_and_last_bounces:
            points3 = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], axis=-1)
            legs = fitted.geometry.device_path(points3)
            out *= unit_phasor(-f.reshape((-1,) + (1,) * legs.ndim) * legs[None])
        if fitted.background is not None:
            out += fitted.background.at(f).reshape((-1,) + (1,) * (out.ndim - 1))
        return out

    def _predict_grid(self, lattice: VoxelLattice, albedo: np.ndarray, layout: GridLayout,
                      f: np.ndarray, options: OperatorOptions) -> np.ndarray:
        fitted = self._stored()
        parts = []
        for start in range(0, f.size, _PREDICT_CHUNK):
            op = SceneOperator(lattice, layout, fitted.geometry, f[start:start + _PREDICT_CHUNK],
                               options)
            parts.append(op.forward(albedo))
        canon = np.concatenate(parts, axis=0)
        return from_canonical(canon, layout.order, axes=(1, 2))

    def _stored(self) -> _Fitted:
        if self._fitted is None:
            raise FitError(f"{MODEL_NAME}: call fit() or load() before predict() or save()")
        return self._fitted

    @property
    def albedo(self) -> np.ndarray:
        """The fitted albedo (Z, Y, X) (relative units) on :attr:`lattice`."""
        return self._stored().albedo

    @classmethod
    def from_albedo(cls, config: RSDPriorConfig, lattice: VoxelLattice, albedo: np.ndarray,
                    geometry: CaptureGeometry, scale: float) -> RSDPriorFieldModel:
        """A fitted model holding ``albedo`` (Z, Y, X) on ``lattice``, in units of the field
        divided by ``scale`` (``neural_volume`` predicts through it)."""
        model = cls(config)
        model._fitted = _Fitted(lattice, np.asarray(albedo, dtype=np.float32), geometry, scale,
                                lobe=config.lobe.exponent)
        return model

    @property
    def background(self) -> WallBackground | None:
        """The fitted offsets b_f (``background: constant``; None otherwise)."""
        return self._stored().background

    @property
    def response(self) -> SystemResponse | None:
        """The fitted system response (None with both of its terms off)."""
        return self._stored().response

    @property
    def lattice(self) -> VoxelLattice:
        """The voxel lattice of the fitted albedo."""
        return self._stored().lattice

    @property
    def n_parameters(self) -> int:
        """Voxels of the albedo."""
        if self._fitted is None:
            raise FitError(f"{MODEL_NAME}: the number of voxels is known after fit or load")
        return self._fitted.lattice.size

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> None:
        fitted = self._stored()
        lat = fitted.lattice
        bg = fitted.background
        extra = {} if bg is None else {"background": bg.values,
                                       "background_frequencies": bg.frequencies}
        write_model_file(path, MODEL_NAME, self.config,
                         {"albedo": fitted.albedo, "depths": lat.depths, **extra},
                         {"origin": list(lat.origin), "step": list(lat.step),
                          "shape": list(lat.shape), "geometry": fitted.geometry.to_dict(),
                          "scale": fitted.scale, "lobe": fitted.lobe,
                          **({} if fitted.response is None
                             else {"response": fitted.response.to_dict()})})

    @classmethod
    def load(cls, path: str | Path) -> RSDPriorFieldModel:
        header, arrays = read_model_file(path, MODEL_NAME)
        try:
            model = cls(stored_config(RSDPriorConfig, header))
            depths = np.asarray(arrays["depths"], dtype=float)
            lattice = VoxelLattice(depths, _pair(header["origin"]), _pair(header["step"]),
                                   (int(header["shape"][0]), int(header["shape"][1])))
            albedo = np.asarray(arrays["albedo"], dtype=np.float32)
            geometry = CaptureGeometry.from_dict(header["geometry"])
            scale = float(header["scale"])
            background = None if "background" not in arrays else WallBackground(
                np.asarray(arrays["background_frequencies"], float),
                np.asarray(arrays["background"], np.complex128))
            response = (SystemResponse.from_dict(header["response"]) if "response" in header
                        else None)
            lobe = float(header.get("lobe", model.config.lobe.exponent))
        except (KeyError, TypeError, ValueError, IndexError, ConfigError, DataError) as err:
            raise DataError(f"model file {path}: invalid {MODEL_NAME} file "
                            f"({type(err).__name__})") from None
        if albedo.shape != lattice.volume_shape or not np.all(np.isfinite(albedo)):
            raise DataError(f"model file {path}: albedo of shape {albedo.shape} does not match "
                            f"the lattice {lattice.volume_shape}")
        model._fitted = _Fitted(lattice, albedo, geometry, scale, background, response, lobe)
        return model


def _pair(values: Sequence[float]) -> tuple[float, float]:
    return float(values[0]), float(values[1])
