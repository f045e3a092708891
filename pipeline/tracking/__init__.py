"""Stage logs written to Rerun (.rrd) and Foxglove MCAP (.mcap) in lock-step (``stage_log``),
and reading them back (``readback``)."""

from pipeline.tracking.readback import (
    mcap_message_counts,
    rerun_executable,
    rrd_entity_paths,
    rrd_equal,
    rrd_recording_id,
    rrd_timelines,
)
from pipeline.tracking.stage_log import StageLog, default_blueprint, topic_for

__all__ = [
    "StageLog",
    "default_blueprint",
    "mcap_message_counts",
    "rerun_executable",
    "rrd_entity_paths",
    "rrd_equal",
    "rrd_recording_id",
    "rrd_timelines",
    "topic_for",
]
