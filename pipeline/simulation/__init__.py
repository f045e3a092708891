"""Physics simulation of box heaps in a bin (pybullet)."""

from pipeline.simulation.heap import (  # noqa: F401
    BoxPose,
    HeapResult,
    build_cell,
    drop_heap,
    settle,
)
