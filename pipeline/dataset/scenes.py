"""The generation artifact's scenes, read back.

Artifact layout (``data/generate/<version>/``)::

    manifest.json          what produced it (see pipeline.artifacts)
    camera.json            intrinsics, T_world_cam, depth unit, bin geometry, box types
    index.json             per split: shard files and the scene indices each holds
    scenes/<split>-<shard:05d>.npz
    log.rrd, log.mcap      Rerun and MCAP logs of the first scenes

Each shard holds ``N`` scenes (``generate.scenes_per_shard``) and ``M`` boxes in all:

    depth         (N, H, W) uint16   z-depth in units of ``depth_unit`` metres (0 = no data), as
                                     the sensor model (``camera.json``'s ``sensor``) returns it
    depth_clean   (N, H, W) uint16   the ideal rendered depth; only when a sensor model or camera
                                     randomisation is on
    mask          (N, H, W) uint8    0 = not a box (bin, ground); k = the scene's k-th box (1-based)
    scene_index   (N,) int64         index of the scene within its split
    seed          (N, 3) int64       the scene's seed: (base seed, split code, scene index)
    num_boxes     (N,) int32         boxes at rest in the bin (the scene's boxes are consecutive)
    num_dropped   (N,) int32         boxes dropped; num_removed boxes left the bin and were removed
    num_removed   (N,) int32
    settle_steps  (N,) int32         physics steps until rest
    settled       (N,) bool          False if the step cap was reached first
    box_type      (M,) int16         index into camera.json's ``box_types``
    box_size      (M, 3) float64     edge lengths along the box's own x, y, z, metres
    box_mass      (M,) float64       kg (artifacts made before it existed: absent, mass = density
                                     x volume)
    box_T_world   (M, 4, 4) float64  pose of the box centre in the world frame
    box_T_cam     (M, 4, 4) float64  pose of the box centre in the camera frame

Compression: deflate level 1; about 27 kB per scene (80 MB for the 3,000 scenes of `default`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from pipeline.artifacts.store import artifact_file
from pipeline.camera.geometry import Intrinsics
from pipeline.dataset.storage import read_npz

SPLITS = ("train", "val", "test")
SPLIT_CODES = {"train": 0, "val": 1, "test": 2}


@dataclass
class Box:
    """A box at rest in the bin. Poses map box-frame points (metres) to world / camera frame."""

    instance: int  # value of this box's pixels in ``Scene.mask``
    type_index: int
    type_name: str
    size: np.ndarray  # (3,) metres
    T_world_box: np.ndarray  # (4, 4)
    T_cam_box: np.ndarray  # (4, 4)
    mass: float | None = None  # kg; None: the box set's density x volume


@dataclass
class Scene:
    """One depth image of a heap and its ground truth.

    Attributes:
        depth_m: (H, W) float32 z-depth along the optical axis, metres; 0.0 = no data. What the
            sensor model returned (the ideal depth with ``sensor=ideal``).
        depth_clean_m: (H, W) float32 ideal z-depth, metres: ``depth_m`` itself when the
            artifact has no sensor model. Labels are computed from it.
        mask: (H, W) uint8 instance mask: 0 = not a box, k = ``boxes[k-1]``.
        boxes: the boxes at rest in the bin.
        intrinsics: camera intrinsics (pixels).
        T_world_cam: (4, 4) camera pose in the world frame (OpenCV camera axes).
        split, index, seed: where the scene comes from; ``seed`` = (base, split code, index).
    """

    depth_m: np.ndarray
    depth_clean_m: np.ndarray
    mask: np.ndarray
    boxes: list[Box]
    intrinsics: Intrinsics
    T_world_cam: np.ndarray
    split: str
    index: int
    seed: tuple[int, int, int]
    settle_steps: int
    settled: bool


class SceneDataset:
    """Random access to one split of a generation artifact: ``len(ds)``, ``ds[i] -> Scene``.

    Shards are read lazily; the most recently used shard is kept in memory.
    """

    def __init__(self, artifact_dir: Path, split: str = "train") -> None:
        if split not in SPLITS:
            raise ValueError(f"unknown split {split!r}; choose one of {SPLITS}")
        self.root = Path(artifact_dir)
        try:
            self.meta = json.loads((self.root / "camera.json").read_text())
            index = json.loads((self.root / "index.json").read_text())
        except FileNotFoundError as e:
            raise FileNotFoundError(
                f"{self.root} is not a generation artifact ({e.filename} missing); "
                "run `make generate` and pass its folder."
            ) from None
        self.split = split
        self.intrinsics = Intrinsics(**self.meta["intrinsics"])
        self.T_world_cam = np.asarray(self.meta["T_world_cam"], dtype=np.float64)
        self.depth_unit = float(self.meta["depth_unit"])
        # the sensor model of the `depth` images (older artifacts: ideal depth)
        self.sensor = self.meta.get("sensor", {"name": "ideal", "enabled": False})
        self.box_types = self.meta["box_types"]
        # The bin the scenes were generated in (same fields as ``conf/bin/*.yaml``).
        self.bin = SimpleNamespace(**self.meta["bin"])
        self._shards = index["splits"][split]  # [{"file": ..., "first": i0, "count": n}, ...]
        # Shard paths, checked to stay inside the artifact folder (ArtifactError otherwise).
        self._paths = [artifact_file(self.root, s["file"]) for s in self._shards]
        self._starts = np.array([s["first"] for s in self._shards], dtype=np.int64)
        self._len = int(sum(s["count"] for s in self._shards))
        self._cache: tuple[int, dict[str, np.ndarray], np.ndarray] | None = None

    def __len__(self) -> int:
        return self._len

    def _shard(self, k: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
        if self._cache is None or self._cache[0] != k:
            arrays = read_npz(self._paths[k])
            box_start = np.concatenate([[0], np.cumsum(arrays["num_boxes"])]).astype(np.int64)
            self._cache = (k, arrays, box_start)
        return self._cache[1], self._cache[2]

    def __getitem__(self, i: int) -> Scene:
        if not -self._len <= i < self._len:
            raise IndexError(
                f"scene {i} out of range for split {self.split!r} of {self._len} scenes"
            )
        i %= self._len
        k = int(np.searchsorted(self._starts, i, side="right") - 1)
        arrays, box_start = self._shard(k)
        row = i - int(self._starts[k])
        b0, b1 = int(box_start[row]), int(box_start[row + 1])
        boxes = [
            Box(
                instance=j + 1,
                type_index=int(arrays["box_type"][b]),
                type_name=self.box_types[int(arrays["box_type"][b])]["name"],
                size=arrays["box_size"][b],
                T_world_box=arrays["box_T_world"][b],
                T_cam_box=arrays["box_T_cam"][b],
                mass=float(arrays["box_mass"][b]) if "box_mass" in arrays else None,
            )
            for j, b in enumerate(range(b0, b1))
        ]
        depth = arrays["depth"][row].astype(np.float32) * np.float32(self.depth_unit)
        clean = (
            arrays["depth_clean"][row].astype(np.float32) * np.float32(self.depth_unit)
            if "depth_clean" in arrays
            else depth
        )
        return Scene(
            depth_m=depth,
            depth_clean_m=clean,
            mask=arrays["mask"][row],
            boxes=boxes,
            intrinsics=self.intrinsics,
            T_world_cam=self.T_world_cam,
            split=self.split,
            index=int(arrays["scene_index"][row]),
            seed=tuple(int(x) for x in arrays["seed"][row]),
            settle_steps=int(arrays["settle_steps"][row]),
            settled=bool(arrays["settled"][row]),
        )

    def __iter__(self):
        for i in range(self._len):
            yield self[i]
