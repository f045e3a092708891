"""Stage logs written to Rerun (.rrd) and Foxglove MCAP (.mcap) in lock-step, plus read-back helpers."""

from pipeline.tracking.stage_log import (  # noqa: F401
    StageLog,
    default_blueprint,
    mcap_message_counts,
    rrd_entity_paths,
    rrd_equal,
    rrd_recording_id,
    rrd_timelines,
    topic_for,
)

__all__ = [
    "StageLog",
    "default_blueprint",
    "mcap_message_counts",
    "rrd_entity_paths",
    "rrd_equal",
    "rrd_recording_id",
    "rrd_timelines",
    "topic_for",
]
