"""Older layouts of metrics.json that still read as the current one.

Each later version only added optional keys or allowed null where a number was required
(6: count splitting, ``capture.thinning`` and ``field.*.splits.heldout_measurement``; 7:
``field.*.fit.fitted``; 8: ``null_reasons`` in each section of scores, null for
``depth_rmse_m``, a ``fitted`` number and the held-out ``excess``), or renamed a key
(9: ``capture.thinning`` is ``capture.count_splitting``, :data:`RENAMED_KEYS`; 10: the
front view's ``scale_invariant_psnr`` and ``front_view_gain`` in each section of scores).
"""

from __future__ import annotations

from typing import Final

from nlosfw.common.errors import DataError

#: The versions :meth:`~nlosfw.pipeline.metrics.RunMetrics.from_json` reads.
READABLE_VERSIONS: Final = (5, 6, 7, 8, 9, 10)

#: Keys renamed since an older version: (the last version that wrote the old name, the
#: section, the old key, the new key); an older file is read with them renamed.
RENAMED_KEYS: Final = ((8, "capture", "thinning", "count_splitting"),)


def metrics_as_current(data: object, current: int, where: str = "") -> object:
    """The JSON object of a metrics.json (``data``) as version ``current`` reads it: an
    older version's with its renamed keys under their new names; a one-line DataError
    naming ``where`` (the file) for a version that is not readable."""
    if not isinstance(data, dict):
        return data                     # the reader says what is wrong with it
    version = data.get("schema_version")
    if version not in READABLE_VERSIONS:
        raise DataError(f"{where + ': ' if where else ''}schema_version is {version!r}; this "
                        f"nlosfw reads versions {', '.join(map(str, READABLE_VERSIONS))} "
                        "(written by another nlosfw version: rerun it, or read it with the "
                        "version that wrote it)")
    if version == current:
        return data
    data = {**data, "schema_version": current}
    for last, section, old, new in RENAMED_KEYS:
        node = data.get(section)
        if isinstance(version, int) and version <= last and isinstance(node, dict) \
                and old in node and new not in node:
            data[section] = {(new if key == old else key): value for key, value in node.items()}
    return data
