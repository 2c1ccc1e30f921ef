"""A nearest-neighbour field model: the simplest possible :class:`nlosfw.FieldModel`."""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from nlosfw import DataError, FieldModel, FieldModelConfig, FitError, FitReport, PhasorField
from nlosfw.common import Choice, config_from_mapping, config_to_dict
from nlosfw.model import check_query, check_training_field

_FORMAT = "nlosfw-example-nearest"


class FrequencyInterpolation(Choice):
    """Between training frequencies: linear interpolation or the nearest one."""

    linear = "linear"
    nearest = "nearest"


@dataclass(frozen=True)
class NearestConfig(FieldModelConfig):
    """Options of the nearest-neighbour model."""

    frequency_interpolation: FrequencyInterpolation = FrequencyInterpolation.linear
    """Between training frequencies: interpolate linearly, or take the nearest one."""


@dataclass(frozen=True, eq=False)
class _Samples:
    """The training samples: wall points (N, 2), sorted frequencies (F,), values (F, N)."""

    xy: np.ndarray
    freqs: np.ndarray
    values: np.ndarray


class NearestFieldModel(FieldModel[NearestConfig]):
    """Copies the nearest training wall sample; interpolates between training frequencies."""

    config_class = NearestConfig
    # what the conformance kit checks (nlosfw.plugins.CAPABILITIES["model"])
    capabilities = ("multi_frequency", "single_frequency", "save_load")

    def __init__(self, config: NearestConfig | Mapping[str, object] | None = None) -> None:
        super().__init__(config)
        self._samples: _Samples | None = None

    def fit(self, field: PhasorField, validation: PhasorField | None = None,
            on_step: Callable | None = None) -> FitReport:
        check_training_field(field, "nearest")
        order = np.argsort(field.frequencies)
        self._samples = _Samples(xy=field.wall_xyz[..., :2].reshape(-1, 2),
                                 freqs=field.frequencies[order],
                                 values=field.values[order].reshape(len(order), -1))
        return FitReport(steps=0, seconds=0.0, final_loss=0.0)

    def predict(self, wall_xy: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        if self._samples is None:
            raise FitError("nearest: predict called before fit or load")
        known = self._samples
        wall_xy, freqs = check_query(wall_xy, frequencies, "nearest")
        _, nearest = cKDTree(known.xy).query(wall_xy.reshape(-1, 2))
        at_points = known.values[:, nearest]                      # (F_train, N)
        if self.config.frequency_interpolation == "nearest" or known.freqs.size == 1:
            idx = np.abs(freqs[:, None] - known.freqs[None]).argmin(axis=1)
            out = at_points[idx]
        else:
            hi = np.clip(np.searchsorted(known.freqs, freqs), 1, known.freqs.size - 1)
            lo = hi - 1
            w = np.clip((freqs - known.freqs[lo]) / (known.freqs[hi] - known.freqs[lo]), 0, 1)
            out = (1 - w)[:, None] * at_points[lo] + w[:, None] * at_points[hi]
        return out.reshape((freqs.size,) + wall_xy.shape[:-1])

    @property
    def n_parameters(self) -> int:
        return 0 if self._samples is None else int(self._samples.values.size * 2)

    def save(self, path: str | Path) -> None:
        if self._samples is None:
            raise FitError("nearest: nothing to save before fit")
        known = self._samples
        header = json.dumps({"format": _FORMAT, "config": config_to_dict(self.config)})
        with open(path, "wb") as f:
            np.savez(f, header=np.array(header), xy=known.xy, freqs=known.freqs,
                     values=known.values)

    @classmethod
    def load(cls, path: str | Path) -> NearestFieldModel:
        try:
            with np.load(path, allow_pickle=False) as data:
                header = json.loads(str(data["header"]))
                arrays = {k: data[k] for k in ("xy", "freqs", "values")}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
            raise DataError(f"{path}: not a nearest field-model file ({err})") from None
        if header.get("format") != _FORMAT:
            raise DataError(f"{path}: holds {header.get('format')!r}, not a nearest model")
        model = cls(config_from_mapping(NearestConfig, header["config"]))
        model._samples = _Samples(xy=arrays["xy"], freqs=arrays["freqs"], values=arrays["values"])
        return model
