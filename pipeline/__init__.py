"""Bin-picking grasp-planning pipeline (reproduction of Jiang et al., Sensors 2020, 20(3), 706).

Folders follow the method: ``simulation/`` builds box heaps in pybullet, ``camera/`` holds
intrinsics, rendering and back-projection, ``artifacts/`` versions and verifies stage outputs,
``tracking/`` writes the Rerun and MCAP logs, and each stage (``generate``, ``report``, ...)
is one module with a pure function and a thin Hydra command line.
"""

__all__ = ["__version__"]
__version__ = "0.1.0"

import os as _os

# Rerun's SDK flushes its log batches every 200 ms by default, so how a .rrd file is split into
# chunks depends on how busy the machine is. Flushing by size (2 MiB) makes that rarer, though
# not impossible (the batcher runs on its own thread), so `make repro-check` compares recordings
# row by row when `rerun rrd compare` (chunk by chunk) reports a difference. Set
# RERUN_FLUSH_TICK_SECS yourself to override.
_os.environ.setdefault("RERUN_FLUSH_TICK_SECS", "1000000000")
