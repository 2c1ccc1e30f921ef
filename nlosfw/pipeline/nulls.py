"""Scores that cannot be computed: null in metrics.json, with why, never NaN or inf.

JSON has no NaN or inf, and a run must always leave its record: on degenerate data (a
zero capture, a scene that reflects nothing, an empty set of samples, a field without
noise) a score may have no value. Each section of scores in
:class:`~nlosfw.pipeline.metrics.RunMetrics` then holds ``null`` for it and, in its
``null_reasons``, one line saying why, by the score's key (``fitted.<name>`` for a number
in a fit's ``fitted``). The builders (:mod:`nlosfw.evaluation`'s scores,
:mod:`nlosfw.pipeline.measure`, the section classes' ``of``) give each reason in words;
:func:`explained`, applied to the whole document when the run ends, turns any NaN or inf
they did not foresee into ``null`` with a reason of its own.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from typing import NamedTuple, TypeVar

import msgspec
from msgspec import inspect as mi

from nlosfw.evaluation.undefined import is_number, not_finite

S = TypeVar("S", bound=msgspec.Struct)
Number = float | int | None

#: The field of a section of scores that says why each of its nulls is null.
REASONS = "null_reasons"

#: The values of an ErrorMetrics that are ratios to the true field (or weighted by it).
RELATIVE = ("relative_l2", "nmse_db", "relative_amplitude_rmse", "phase_error")
#: Every value of an ErrorMetrics that may be null.
ERRORS = ("relative_l2", "nmse_db", "amplitude_rmse", "relative_amplitude_rmse", "phase_error")


def error_values(values: Mapping[str, Number]) -> tuple[dict[str, float | None],
                                                        dict[str, str]]:
    """The errors of one set (:func:`nlosfw.evaluation.error_metrics`'s values but
    ``n_samples``) with every one that is not a finite number None, and why each None is."""
    out: dict[str, float | None] = {}
    reasons: dict[str, str] = {}
    n_samples = int(values.get("n_samples") or 0)
    zero_truth = values.get("relative_l2") == math.inf
    for key in ERRORS:
        value = values.get(key)
        out[key] = float(value) if value is not None and is_number(value) else None
        if out[key] is not None:
            continue
        if n_samples == 0:
            reasons[key] = "the set is empty: no samples to score"
        elif key == "nmse_db" and value == -math.inf:
            reasons[key] = "the prediction is exact on these samples: zero error (-inf dB)"
        elif zero_truth and key in RELATIVE:
            reasons[key] = ("the true field is zero on these samples: an error relative to it "
                            "is undefined")
        else:
            reasons[key] = not_finite(math.nan if value is None else float(value))
    return out, reasons


class FitValues(NamedTuple):
    """A fit report's numbers as recorded: each NaN or inf None, with why."""

    final_loss: float | None
    best_val_loss: float | None
    fitted: dict[str, float | None]
    reasons: dict[str, str]


def fit_values(final_loss: float | None, best_val_loss: float | None,
               fitted: Mapping[str, float]) -> FitValues:
    """A fit report's losses and fitted numbers with each NaN or inf None, and why."""
    reasons: dict[str, str] = {}
    losses: dict[str, float | None] = {"final_loss": final_loss, "best_val_loss": best_val_loss}
    for key, loss in losses.items():
        if loss is not None and not is_number(loss):
            losses[key] = None
            reasons[key] = f"the fit reported a loss of {float(loss)!r}"
    numbers: dict[str, float | None] = {}
    for name, value in fitted.items():
        numbers[name] = float(value) if is_number(value) else None
        if numbers[name] is None:
            reasons[f"fitted.{name}"] = (f"the fit computed {float(value)!r} for it: "
                                         "undefined on this capture")
    return FitValues(losses["final_loss"], losses["best_val_loss"], numbers, reasons)


def with_explicit_nulls(data: dict[str, object]) -> dict[str, object]:
    """``data`` (the JSON of a document) with a ``null`` for each key of a
    ``null_reasons`` its section lacks (one that may be absent, such as ``depth_rmse_m``),
    placed before ``null_reasons``."""
    out = _explicit(data)
    return out if isinstance(out, dict) else data


def _explicit(node: object) -> object:
    if isinstance(node, list):
        return [_explicit(v) for v in node]
    if not isinstance(node, dict):
        return node
    out = {k: _explicit(v) for k, v in node.items()}
    reasons = out.get(REASONS)
    if not isinstance(reasons, dict):
        return out
    missing = [k for k in reasons if "." not in k and k not in out]
    ordered: dict[str, object] = {}
    for key, value in out.items():
        if key == REASONS:
            ordered.update(dict.fromkeys(missing))
        ordered[key] = value
    return ordered


def explained(document: S) -> S:
    """``document`` with every NaN or inf, in a section that has ``null_reasons``, made
    None with a generic reason (a reason already there is kept)."""
    return _walk(document)  # type: ignore[return-value]


def _walk(value: object) -> object:
    if isinstance(value, msgspec.Struct):
        return _struct(value)
    if isinstance(value, dict):
        return {k: _walk(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return tuple(_walk(v) for v in value)
    return value


def _struct(document: msgspec.Struct) -> msgspec.Struct:
    changes: dict[str, object] = {}
    nullable = _nullable_fields(type(document))
    reasons = dict(getattr(document, REASONS, None) or {})
    for name in document.__struct_fields__:
        value = getattr(document, name)
        if REASONS in nullable and name in nullable and isinstance(value, float) and (
                not math.isfinite(value)):
            changes[name] = None
            reasons.setdefault(name, not_finite(value))
        elif REASONS in nullable and isinstance(value, dict) and any(
                isinstance(v, float) and not math.isfinite(v) for v in value.values()):
            changes[name] = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                             for k, v in value.items()}
            for key, item in value.items():
                if isinstance(item, float) and not math.isfinite(item):
                    reasons.setdefault(f"{name}.{key}", not_finite(item))
        elif isinstance(value, (msgspec.Struct, dict, tuple)):
            walked = _walk(value)
            if walked is not value:
                changes[name] = walked
    if reasons != (getattr(document, REASONS, None) or {}):
        changes[REASONS] = reasons
    return msgspec.structs.replace(document, **changes) if changes else document


@functools.cache
def _nullable_fields(cls: type) -> frozenset[str]:
    """The fields of document class ``cls`` that may hold None (``X | None`` or absent)."""
    info = mi.type_info(cls)
    if not isinstance(info, mi.StructType):
        return frozenset()
    out = set()
    for field in info.fields:
        node = field.type.type if isinstance(field.type, mi.Metadata) else field.type
        if field.default is None or (isinstance(node, mi.UnionType) and any(
                isinstance(t, mi.NoneType) for t in node.types)):
            out.add(field.name)
    return frozenset(out)
