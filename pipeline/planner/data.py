"""Training data: depth images of a generation artifact with the grid targets of its labels.

The network input's depth normalisation is ``pipeline.planner.normalisation``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import torch

from pipeline.dataset.scenes import SceneDataset
from pipeline.dataset.storage import read_npz
from pipeline.planner import distributed
from pipeline.planner.augment import flip_image, flip_rows
from pipeline.planner.distributed import DistContext
from pipeline.planner.normalisation import Normalisation, normalise_depth
from pipeline.planner.targets import encode, stack_targets


class DepthShards:
    """Random access to one split's depth images without holding them in memory.

    The generation artifact stores depth deflate-compressed, a shard of N images per member,
    so reading one image would inflate the whole shard. On first use each shard's depth is
    written once, uncompressed, to ``<cache>/<split>-<shard>-<sha256[:16]>.npy`` ((N, H, W)
    uint16, the generation's depth unit); an image is then one ``pread`` of H·W·2 bytes (no
    memory map, so the process's memory does not grow with the data it has read). The file
    name carries the source shard's hash from the generation manifest: an altered artifact
    never reuses a stale cache. Files are written atomically (temporary name, then rename), so
    several processes (DataLoader workers, DDP ranks) may build the cache at the same time.

    Args:
        gen_dir: generation artifact folder.
        split: "train", "val" or "test".
        cache_dir: folder for the uncompressed shards (``<data>/.cache/depth/<gen version>``).
        limit: use only the first ``limit`` images (0 = all).
    """

    def __init__(self, gen_dir: Path, split: str, cache_dir: Path, limit: int = 0) -> None:
        ds = SceneDataset(gen_dir, split)
        self.intrinsics, self.depth_unit = ds.intrinsics, ds.depth_unit
        self.shape = (ds.intrinsics.height, ds.intrinsics.width)
        self._len = len(ds) if limit <= 0 else min(limit, len(ds))
        files = json.loads((Path(gen_dir) / "manifest.json").read_text())["files"]
        self.cache_dir = Path(cache_dir)
        self._files: list[Path] = []
        self._offsets: list[int] = []
        self._starts = np.array([s["first"] for s in ds._shards], dtype=np.int64)
        for k, shard in enumerate(ds._shards):
            if shard["first"] >= self._len:
                break
            sha = files[shard["file"]]["sha256"]
            path = self.cache_dir / f"{split}-{k:05d}-{sha[:16]}.npy"
            if not path.is_file():
                self._write(path, read_npz(Path(gen_dir) / shard["file"])["depth"])
            self._files.append(path)
            self._offsets.append(_npy_data_offset(path, self.shape))

    @staticmethod
    def _write(path: Path, depth: np.ndarray) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f"{path.name}.{os.getpid()}.part")
        with open(tmp, "wb") as f:
            np.save(f, np.ascontiguousarray(depth, dtype="<u2"), allow_pickle=False)
        os.replace(tmp, path)

    def __len__(self) -> int:
        return self._len

    def raw(self, i: int) -> np.ndarray:
        """(H, W) uint16 depth of image ``i`` in the generation's depth unit (0 = no data)."""
        if not 0 <= i < self._len:
            raise IndexError(f"image {i} out of range ({self._len} images)")
        k = int(np.searchsorted(self._starts, i, side="right") - 1)
        row, pixels = i - int(self._starts[k]), self.shape[0] * self.shape[1]
        out = np.fromfile(
            self._files[k], dtype="<u2", count=pixels, offset=self._offsets[k] + 2 * pixels * row
        )
        if out.size != pixels:
            raise ValueError(f"{self._files[k]} is truncated; delete {self.cache_dir} and rerun")
        return out.reshape(self.shape)


def _npy_data_offset(path: Path, shape: tuple[int, int]) -> int:
    """Byte offset of the array data in an ``.npy`` file, after checking dtype and shape."""
    with open(path, "rb") as f:
        version = np.lib.format.read_magic(f)
        header = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )(f)
        array_shape, fortran, dtype = header
        if fortran or dtype != np.dtype("<u2") or tuple(array_shape[1:]) != tuple(shape):
            raise ValueError(
                f"{path} is not a depth cache file of {shape} uint16 images; delete it and rerun"
            )
        return f.tell()


# The label fields the loss, the flips and Table 1 read.
ROW_FIELDS = ("uv", "grasp_class", "center_cam", "normal_cam", "x_axis_cam")


class GraspDataset(torch.utils.data.Dataset):
    """One split for training: depth streamed from disk (``DepthShards``), label rows in memory
    (about 1 kB an image: 15,000 images ≈ 15 MB).

    ``dataset[(i, flip)]`` → (x (H, W) float32 network input, targets of ``encode``), the item a
    ``torch.utils.data.DataLoader`` worker decodes; ``collate`` stacks a batch of them.
    ``batch(indices, flips)`` does the same in this process → (x (B, 1, H, W), targets).
    ``lost_points`` / ``total_points``: points dropped by the one-point-per-cell rule.
    """

    def __init__(
        self,
        gen_dir: Path,
        labels,
        split: str,
        norm: Normalisation,
        grid: int,
        hand_cfg=None,
        limit: int = 0,
        cache_dir: Path | None = None,
    ) -> None:
        gen_dir = Path(gen_dir)
        cache_dir = (
            Path(cache_dir)
            if cache_dir is not None
            else (gen_dir.parent.parent / ".cache" / "depth" / gen_dir.name)
        )
        self.depth = DepthShards(gen_dir, split, cache_dir, limit)
        n = len(self.depth)
        if len(labels) < n:
            raise ValueError(
                f"the label artifact has {len(labels)} {split} images, the "
                f"generation artifact {n}: they do not belong together"
            )
        self.intrinsics = self.depth.intrinsics
        self.depth_unit = self.depth.depth_unit
        self.norm, self.grid, self.hand_cfg = norm, grid, hand_cfg
        self.rows = []
        self.lost_points = self.total_points = 0
        width = self.intrinsics.width
        for i in range(n):
            rows = labels[i]
            self.rows.append({k: rows[k] for k in ROW_FIELDS})
            self.lost_points += encode(rows["uv"], rows["grasp_class"], grid, width)["lost"]
            self.total_points += len(rows["uv"])

    def __len__(self) -> int:
        return len(self.rows)

    def depth_m(self, i: int) -> np.ndarray:
        """(H, W) float32 metres, 0 = no data."""
        return self.depth.raw(int(i)).astype(np.float32) * np.float32(self.depth_unit)

    def __getitem__(self, key) -> tuple[np.ndarray, dict]:
        i, flip = key if isinstance(key, tuple) else (key, "none")
        depth, rows = self.depth_m(int(i)), self.rows[int(i)]
        if flip != "none":
            depth = flip_image(depth, flip)
            rows = flip_rows(rows, flip, self.intrinsics, self.hand_cfg)
        return (
            normalise_depth(depth, self.norm),
            encode(rows["uv"], rows["grasp_class"], self.grid, depth.shape[1]),
        )

    @staticmethod
    def collate(items) -> tuple[torch.Tensor, dict]:
        """[(x (H, W), targets), ...] → (x (B, 1, H, W) float32, ``stack_targets`` batch)."""
        return (
            torch.from_numpy(np.stack([x for x, _ in items])[:, None]),
            stack_targets([t for _, t in items]),
        )

    def batch(self, indices, flips=None) -> tuple[torch.Tensor, dict]:
        flips = flips if flips is not None else ["none"] * len(indices)
        return self.collate([self[(int(i), f)] for i, f in zip(indices, flips)])


def make_loader(
    data: GraspDataset, batches: list[list[tuple[int, str]]], workers: int, prefetch: int = 4
) -> torch.utils.data.DataLoader:
    """Batches of ``data`` in the given order (each a list of (index, flip)), decoded by
    ``workers`` processes (0 = in this process). The order, hence the result, does not depend on
    ``workers``."""
    kwargs = {"prefetch_factor": prefetch} if workers > 0 else {}
    # Its own generator: creating the loader's iterator draws a seed, and drawing it from
    # torch's global generator would change the random stream the training sees.
    return torch.utils.data.DataLoader(
        data,
        batch_sampler=batches,
        collate_fn=data.collate,
        num_workers=workers,
        generator=torch.Generator().manual_seed(0),
        **kwargs,
    )


def epoch_order(n: int, seed: int, epoch: int, flip: str) -> tuple[list[int], list[str]]:
    """Epoch ``epoch``'s image order and per-image flips, from (seed, epoch) only."""
    gen = torch.Generator().manual_seed(seed * 1_000_003 + epoch)
    order = torch.randperm(n, generator=gen).tolist()
    choices = {
        "none": ["none"],
        "u": ["none", "u"],
        "v": ["none", "v"],
        "uv": ["none", "u", "v", "uv"],
    }[flip]
    picks = torch.randint(len(choices), (n,), generator=gen).tolist()
    return order, [choices[k] for k in picks]


def epoch_batches(
    n: int, batch: int, seed: int, epoch: int, flip: str, ctx: DistContext
) -> tuple[list[list[tuple[int, str]]], list[float]]:
    """Epoch ``epoch``'s batches for this rank, as (index, flip) lists, and their loss weights
    (``distributed.split_batch``; one process: the whole batches, weight 1)."""
    order, flips = epoch_order(n, seed, epoch, flip)
    batches, weights = [], []
    for start in range(0, n, batch):
        idx, fl, w = distributed.split_batch(
            order[start : start + batch], flips[start : start + batch], ctx.rank, ctx.world_size
        )
        batches.append(list(zip(idx, fl)))
        weights.append(w)
    return batches, weights
