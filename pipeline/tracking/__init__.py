"""Stage logs written to Rerun (.rrd) and Foxglove MCAP (.mcap) in lock-step, plus read-back helpers.

The public names are those of ``pipeline.tracking.stage_log`` (its ``__all__``)."""

from pipeline.tracking import stage_log
from pipeline.tracking.stage_log import *  # noqa: F401,F403

__all__ = list(stage_log.__all__)
