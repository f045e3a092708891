"""Bin-picking grasp-planning pipeline (reproduction of Jiang et al., Sensors 2020, 20(3), 706).

Folders follow the method and its layers (docs/architecture.md): ``stages/`` holds the
pipeline's stages (generate, label, train, baseline, evaluate, unseen, ablation, robustness),
each a pure function of its config and inputs with a thin Hydra command line; ``report/`` is the
report stage and ``tools/`` the tools (bench, view, verify, repro-check, profile). The libraries
beneath them: ``world/`` (the simulated cell of the closed loop) and ``controller/``,
``servo/``, ``planner/``, ``dexnet/`` (the robot side), ``labelling/``, ``grasping/``,
``simulation/``, ``robot/``, ``dataset/``, ``camera/`` and ``cell/``; ``runtime/``,
``artifacts/``, ``tracking/`` and ``config/`` run stages, version their outputs, write the
Rerun and MCAP logs and hold the configuration schema.
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
