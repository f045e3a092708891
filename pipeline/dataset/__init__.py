"""Reading and writing scene data: compact shards and a ``Dataset``-style loader."""

from pipeline.dataset.scenes import (  # noqa: F401
    SPLITS,
    Box,
    Scene,
    SceneDataset,
)
from pipeline.dataset.storage import read_npz, write_npz  # noqa: F401
