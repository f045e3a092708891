"""Deterministic ``.npz`` files.

``numpy.savez_compressed`` stamps each member with the current time, so two runs that compute
identical arrays write different bytes. ``write_npz`` fixes the timestamp and member order, so an
artifact's file hashes depend on its contents only. The files are ordinary ``.npz``: ``np.load``
reads them.
"""

from __future__ import annotations

import io
import os
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

_FIXED_DATE = (1980, 1, 1, 0, 0, 0)


def write_npz(path: Path, arrays: Mapping[str, np.ndarray], compresslevel: int = 1) -> None:
    """Write arrays to ``path`` (deflate, level ``compresslevel``) atomically and reproducibly."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    with zipfile.ZipFile(
        tmp, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=compresslevel
    ) as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(name + ".npy", date_time=_FIXED_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue(), compresslevel=compresslevel)
    os.replace(tmp, path)


def read_npz(path: Path) -> dict[str, np.ndarray]:
    """All arrays of an ``.npz`` file (no pickled objects are ever loaded)."""
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def shard_index(tasks, work_dir: Path, splits, path_of) -> dict[str, list[dict]]:
    """Each split's shards in an artifact's index: ``{"file"`` (``path_of(task)`` relative to
    ``work_dir``), ``"first"`` (the first scene's index in the split), ``"count"}``, in the
    order of ``tasks`` (objects with ``split``, ``first``, ``count``)."""
    index: dict[str, list[dict]] = {s: [] for s in splits}
    for t in tasks:
        rel = Path(path_of(t)).relative_to(work_dir).as_posix()
        index[t.split].append({"file": rel, "first": t.first, "count": t.count})
    return index
