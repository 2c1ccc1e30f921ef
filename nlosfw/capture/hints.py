"""Imaging hints: the settings a capture states for its imaging, attached to the capture.

A capture's typed ``imaging_hints`` (:class:`ImagingHints`) may say which radiometric
falloff to undo (``diffuse`` 1/r^4 or ``retroreflective`` 1/r^2), the Wiener filter's
signal-to-noise ratio and a depth window. Nothing here looks a capture up by its file's
name, path or content: hints come only from what a file itself states (or a caller
attaches). The transient imagers (``lct``, ``fk``, ``fbp``) use them when their own options
``falloff`` and ``snr`` are not set, and estimate what neither gives from the data
(:mod:`nlosfw.image.data_settings`); an option given explicitly always wins. The
phasor-field transform copies them to the field's ``imaging_hints``, so an imager that gets
only a field sees them too. On disk they stay where y-tal's layout keeps free metadata
(``scene_info["imaging_hints"]``, :data:`HINTS_KEY`); a capture or field read from such a
mapping takes them out of it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from nlosfw.capture.data import Capture

#: The key of the hints in a capture file's ``scene_info`` (and in the metadata of fields
#: and captures written before the hints were typed attributes).
HINTS_KEY = "imaging_hints"


@dataclass(frozen=True)
class ImagingHints:
    """How a capture states it is imaged; ``None`` fields: no hint (the imager estimates
    or defaults)."""

    falloff: str | None = None
    """``diffuse`` (1/r^4) or ``retroreflective`` (1/r^2)."""
    snr: float | None = None
    """Signal-to-noise ratio of the LCT Wiener filter."""
    depth_window: tuple[float, float] | None = None
    """[near, far] (m) of the depths the capture's scene lies in."""
    origin: str = ""
    """Where the hints come from (shown in metrics and reports)."""

    def to_dict(self) -> dict[str, object]:
        """Plain values for ``scene_info`` (YAML/JSON)."""
        out: dict[str, object] = {"origin": self.origin}
        if self.falloff is not None:
            out["falloff"] = self.falloff
        if self.snr is not None:
            out["snr"] = float(self.snr)
        if self.depth_window is not None:
            out["depth_window"] = [float(v) for v in self.depth_window]
        return out

    @classmethod
    def from_mapping(cls, mapping: object) -> ImagingHints:
        """The hints a ``scene_info``/metadata entry holds; unknown or bad values are ignored
        (hints are advice: a file cannot make an imager fail through them)."""
        if not isinstance(mapping, Mapping):
            return cls()
        falloff = mapping.get("falloff")
        snr = mapping.get("snr")
        window: tuple[float, float] | None = None
        given = mapping.get("depth_window")
        if (isinstance(given, (list, tuple)) and len(given) == 2
                and all(isinstance(v, (int, float)) for v in given)
                and 0 <= float(given[0]) < float(given[1])):
            window = (float(given[0]), float(given[1]))
        return cls(
            falloff=falloff if falloff in ("diffuse", "retroreflective") else None,
            snr=float(snr) if isinstance(snr, (int, float)) and 0 < float(snr) < 1e12 else None,
            depth_window=window,
            origin=str(mapping.get("origin", "")))


def capture_hints(capture: Capture) -> ImagingHints:
    """The hints attached to ``capture`` (empty hints when none are)."""
    return capture.imaging_hints or ImagingHints()


def with_hints(capture: Capture, hints: ImagingHints) -> Capture:
    """A copy of ``capture`` carrying ``hints``."""
    return capture.replace(imaging_hints=hints)


def hints_from(info: Mapping[str, object]) -> tuple[dict[str, object], ImagingHints | None]:
    """(``info`` without :data:`HINTS_KEY`, the hints it held or None): how a capture's
    ``scene_info`` or a field's metadata written with the hints in it is read."""
    if HINTS_KEY not in info:
        return dict(info), None
    rest = {k: v for k, v in info.items() if k != HINTS_KEY}
    return rest, ImagingHints.from_mapping(info[HINTS_KEY])
