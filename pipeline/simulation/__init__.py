"""Physics simulation of box heaps in a bin (pybullet)."""

from pipeline.simulation.heap import (  # noqa: F401
    BoxPose,
    HeapResult,
    drop_heap,
    settle,
)
