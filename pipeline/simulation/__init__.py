"""Physics simulation of box heaps in a bin (pybullet)."""

from pipeline.simulation.heap import BoxPose, HeapResult, drop_heap, settle  # noqa: F401
