"""Reading stage logs back: the entity paths, timelines and recording id of an .rrd file, the
message counts of an .mcap file, and whether two .rrd files hold the same data (``make
repro-check``, the tests)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path


def rrd_entity_paths(path: Path) -> set[str]:
    """Entity paths of the first recording in an .rrd file (as Rerun prints them: ``/world/…``)."""
    from rerun.chunk import RrdReader

    store = RrdReader(path).stream().collect()
    return {str(c.entity_path) for c in store.stream()}


def rrd_timelines(path: Path) -> set[str]:
    """Names of all timelines used by the first recording in an .rrd file (blueprint excluded).

    A :class:`StageLog` recording holds only the caller's timelines (no ``log_time``)."""
    from rerun.chunk import RrdReader

    store = RrdReader(path).stream().collect()
    return {str(t) for c in store.stream() for t in c.timeline_names}


def rrd_recording_id(path: Path) -> str:
    """Recording id of the first recording in an .rrd file."""
    from rerun.chunk import RrdReader

    recs = RrdReader(path).recordings()
    if not recs:
        raise ValueError(f"{path} holds no recording")
    return str(recs[0].recording_id)


def mcap_message_counts(path: Path) -> dict[str, int]:
    """Topic -> message count, from the MCAP summary statistics (no message decoding)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        raise ValueError(f"{path} has no summary statistics")
    counts: dict[str, int] = {ch.topic: 0 for ch in summary.channels.values()}
    for cid, n in summary.statistics.channel_message_counts.items():
        topic = summary.channels[cid].topic
        counts[topic] = counts.get(topic, 0) + n
    return counts


def rerun_executable() -> str:
    """The ``rerun`` CLI of this interpreter's environment (by ``sys.executable``), else PATH."""
    here = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if here.exists():
        return str(here)
    found = shutil.which("rerun")
    if found is None:
        raise FileNotFoundError("rerun CLI not found next to sys.executable nor on PATH")
    return found


def rrd_equal(a: Path, b: Path) -> bool:
    """True iff ``rerun rrd compare a b`` exits 0 (same data; the ``log_time`` timeline ignored)."""
    res = subprocess.run(
        [rerun_executable(), "rrd", "compare", str(a), str(b)], capture_output=True, text=True
    )
    return res.returncode == 0
