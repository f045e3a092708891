"""repro-check compares Rerun recordings by their rows, whatever the chunking."""

import time

import rerun as rr

from pipeline.tools.repro_check import rrd_rows_equal


def _record(path, pause: bool, last: float = 5.0) -> None:
    rec = rr.RecordingStream("t", recording_id="x", send_properties=False)
    rec.set_log_time_enabled(False)
    rec.save(str(path))
    for i in range(4):
        rec.set_time("s", sequence=i)
        rec.log("a", rr.Scalars(float(i) if i < 3 else last))
        rec.flush()  # one chunk per row ...
        if pause:
            time.sleep(0.01)
    rec.disconnect()


def test_same_rows_other_chunks_are_equal_and_other_values_are_not(tmp_path):
    _record(tmp_path / "a.rrd", pause=True)
    rec = rr.RecordingStream("t", recording_id="x", send_properties=False)
    rec.set_log_time_enabled(False)
    rec.save(str(tmp_path / "b.rrd"))
    for i in range(4):  # ... and here all four rows in one chunk
        rec.set_time("s", sequence=i)
        rec.log("a", rr.Scalars(float(i) if i < 3 else 5.0))
    rec.disconnect()
    _record(tmp_path / "c.rrd", pause=False, last=6.0)
    assert rrd_rows_equal(tmp_path / "a.rrd", tmp_path / "b.rrd")
    assert not rrd_rows_equal(tmp_path / "a.rrd", tmp_path / "c.rrd")


def _timed(path, seconds: float) -> None:
    rec = rr.RecordingStream("t", recording_id="x", send_properties=False)
    rec.set_log_time_enabled(False)
    rec.save(str(path))
    rec.set_time("d", duration=seconds)
    rec.set_time("w", timestamp=1_700_000_000.0 + seconds)
    rec.log("a", rr.Scalars(1.0))
    rec.disconnect()


def test_nanosecond_duration_and_timestamp_timelines_are_compared(tmp_path):
    # 1.5 µs past a whole second: not a whole microsecond, which Python's timedelta cannot hold
    _timed(tmp_path / "a.rrd", 2.0000015)
    _timed(tmp_path / "b.rrd", 2.0000015)
    _timed(tmp_path / "c.rrd", 2.0000025)
    assert rrd_rows_equal(tmp_path / "a.rrd", tmp_path / "b.rrd")
    assert not rrd_rows_equal(tmp_path / "a.rrd", tmp_path / "c.rrd")
