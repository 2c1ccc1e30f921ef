"""Field-model files: a portable ``.npz`` holding a JSON header and named numpy arrays.

Every field model (neural or not, any backend) writes this one format, so a
file written by one backend loads in another and nothing needs pickle.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from nlosfw.common.config import config_from_mapping, config_to_dict, with_current_names
from nlosfw.common.errors import ConfigError, DataError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

C = TypeVar("C")

#: Format tag written in every field-model file.
FILE_FORMAT = "nlosfw-field-model"
FILE_VERSION = 2
#: Versions :func:`read_model_file` reads (1: neural fields stored [W0, b0, ...] as p0, p1, ...).
READABLE_VERSIONS = (1, 2)


def write_model_file(path: str | Path, model: str, config: DataclassInstance,
                     arrays: Mapping[str, np.ndarray],
                     extra: Mapping[str, object] | None = None) -> None:
    """Write a portable ``.npz``: a JSON header (format, model name, config, extra) + arrays.

    ``path`` is used as given (no ``.npz`` suffix is appended).
    """
    header = {"format": FILE_FORMAT, "version": FILE_VERSION, "model": model,
              "config": config_to_dict(config), **dict(extra or {})}
    payload: dict[str, Any] = {f"a_{k}": np.asarray(v) for k, v in arrays.items()}
    payload["header"] = np.array(json.dumps(header))
    with open(Path(path), "wb") as fh:
        np.savez(fh, **payload)


def read_model_file(path: str | Path, expected: str | tuple[str, ...]
                    ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """(header, arrays) of a file written by :func:`write_model_file` for model ``expected``.

    Raises a one-line :class:`DataError` for a missing, corrupt or foreign file.
    """
    path = Path(path)
    names = (expected,) if isinstance(expected, str) else tuple(expected)
    if not path.is_file():
        raise DataError(f"model file {path}: does not exist")
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"][()]))
            arrays = {k[2:]: np.array(data[k]) for k in data.files if k.startswith("a_")}
    except Exception as err:  # zipfile, pickle, json and key errors all mean "not ours"
        raise DataError(f"model file {path}: not a readable nlosfw field-model file "
                        f"(corrupt or another format: {type(err).__name__})") from None
    if not isinstance(header, dict) or header.get("format") != FILE_FORMAT:
        raise DataError(f"model file {path}: not an nlosfw field-model file")
    if header.get("version") not in READABLE_VERSIONS:
        raise DataError(f"model file {path}: format version {header.get('version')} is not "
                        f"supported (expected one of {READABLE_VERSIONS})")
    if header.get("model") not in names:
        raise DataError(f"model file {path}: holds a {header.get('model')!r} field model, not "
                        f"{' or '.join(repr(n) for n in names)}")
    return header, arrays


def stored_config(cls: type[C], header: Mapping[str, object]) -> C:
    """The config (dataclass ``cls``) a model file's ``header`` holds, its options renamed
    since the file was written read under their new names
    (:func:`~nlosfw.common.config.with_current_names`); a ConfigError (``model.<option>``)
    for an option ``cls`` does not have. A KeyError when the header holds no config."""
    stored = header["config"]
    if not isinstance(stored, Mapping):
        raise ConfigError("model", f"the stored config is not a mapping of options: {stored!r}")
    return config_from_mapping(cls, with_current_names(cls, stored), "model")
