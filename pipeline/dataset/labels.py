"""A label artifact's grasp-point rows (written by the labelling stage), read back per scene.

``labels/<split>-<shard>.npz`` holds one row per grasp point, aligned with the generation
shards; ``LABEL_FIELDS`` names every array with its shape, dtype, frame and unit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.artifacts.store import artifact_file
from pipeline.dataset.storage import read_npz

# One row per grasp point in labels/<split>-<shard>.npz:
LABEL_FIELDS = {
    "scene_index": "(P,) int64 scene index within the split",
    "instance": "(P,) int16 the box's value in the scene's instance mask",
    "uv": "(P, 2) float32 grasp point g in pixels (u, v)",
    "center_cam": "(P, 3) float32 surface centre, camera frame, m",
    "normal_cam": "(P, 3) float32 unit normal towards the camera",
    "long_axis_cam": "(P, 3) float32",
    "short_axis_cam": "(P, 3) float32",
    "lengths": "(P, 2) float32 L_l, L_s in m",
    "area": "(P,) float32 m^2",
    "x_axis_cam": "(P, 3) float32 the surface axis the hand's X is aligned with",
    "theta_deg": "(P, 2) float32 θ1, θ2 (warped view), degrees",
    "hand_class": "(P,) int8 hand-level class (0 R, 1 L, 2 B, 3 NG)",
    "grasp_class": "(P,) int8 final class after the robot-level check",
    "ng_reason": "(P,) int8 index into NG_REASONS ('' when graspable)",
    "num_points": "(P,) int32 RANSAC inliers",
    "points_per_scene": "(N,) int32 grasp points of each scene of the shard (rows are in order)",
}


class LabelSet:
    """Read a label artifact back: ``LabelSet(folder, split)[i]`` → dict of the scene's rows."""

    def __init__(self, folder: Path, split: str) -> None:
        self.folder = Path(folder)
        meta = json.loads((self.folder / "labels.json").read_text())
        self.shards = meta["splits"][split]
        # Shard paths, checked to stay inside the artifact folder (ArtifactError otherwise).
        self._paths = [artifact_file(self.folder, s["file"]) for s in self.shards]
        self._starts = np.array([s["first"] for s in self.shards], dtype=np.int64)
        self._len = int(sum(s["count"] for s in self.shards))
        self._cache = None

    def __len__(self) -> int:
        return self._len

    def __getitem__(self, i: int) -> dict[str, np.ndarray]:
        if not 0 <= i < self._len:
            raise IndexError(f"scene {i} out of range ({self._len} scenes)")
        k = int(np.searchsorted(self._starts, i, side="right") - 1)
        if self._cache is None or self._cache[0] != k:
            arrays = read_npz(self._paths[k])
            starts = np.concatenate([[0], np.cumsum(arrays["points_per_scene"])])
            self._cache = (k, arrays, starts)
        _, arrays, starts = self._cache
        row = i - int(self._starts[k])
        a, b = int(starts[row]), int(starts[row + 1])
        return {key: v[a:b] for key, v in arrays.items() if key != "points_per_scene"}
