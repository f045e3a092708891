"""Bin-picking grasp-planning pipeline (reproduction of Jiang et al., Sensors 2020, 20(3), 706).

Folders follow the method: ``simulation/`` builds box heaps in pybullet, ``camera/`` holds
intrinsics, rendering and back-projection, ``artifacts/`` versions and verifies stage outputs,
``tracking/`` writes the Rerun and MCAP logs, and each stage (``generate``, ``report``, ...)
is one module with a pure function and a thin Hydra command line.
"""

__all__ = ["__version__"]
__version__ = "0.1.0"
