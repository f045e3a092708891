"""Reading and writing scene data: compact shards and a ``Dataset``-style loader."""

from pipeline.dataset.scenes import SPLITS, Box, Scene, SceneDataset  # noqa: F401
from pipeline.dataset.storage import read_npz, write_npz  # noqa: F401
