"""StageLog writes matching, reproducible Rerun (.rrd) and Foxglove MCAP (.mcap) logs."""

from __future__ import annotations

import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from pipeline.tracking import (
    StageLog,
    default_blueprint,
    mcap_message_counts,
    rrd_entity_paths,
    rrd_equal,
    rrd_recording_id,
    rrd_timelines,
    topic_for,
)
from pipeline.tracking.readback import rerun_executable
from pipeline.tracking.stage_log import quat_xyzw_from_matrix

H, W = 6, 8
N_SCENES = 3
EMPTY_SCENE = 1  # the scene logged with 0 boxes
INTR = SimpleNamespace(width=W, height=H, fx=10.0, fy=11.0, cx=3.5, cy=2.5)
CAM = "world/camera"
DEPTH = f"{CAM}/depth"
SEG = f"{CAM}/segmentation"
BOXES = "world/boxes"
BIN = "world/bin"
SCALAR = "metrics/iou"
TEXT = "log"


@pytest.fixture(autouse=True)
def _rerun_strict():
    """Make Rerun raise on malformed archetypes instead of only warning."""
    old = rr.strict_mode()
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(old)


def scene_depth(i: int, bump: float = 0.0) -> np.ndarray:
    d = (0.5 + 0.01 * np.arange(H * W, dtype=np.float32).reshape(H, W) + 0.1 * i).astype(np.float32)
    d[0, 0] = 0.0  # no data
    d[2, 3] += np.float32(bump)
    return d


def write_log(folder: Path, bump: float = 0.0) -> None:
    """Three scenes: camera, depth, mask, 2 boxes (0 in EMPTY_SCENE), scalar, text; a static bin."""
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking straight down
    T[:3, 3] = [0.0, 0.0, 1.2]
    with StageLog(folder, "test_tracking", "rec-0001", blueprint=default_blueprint(CAM)) as log:
        log.log_boxes(
            BIN,
            [[0.0, 0.0, 0.05]],
            [[0.6, 0.4, 0.1]],
            [[0, 0, 0, 1.0]],
            labels=["bin"],
            static=True,
        )
        for i in range(N_SCENES):
            log.set_time(
                sequences={"scene": i}, durations_s={"sim_time": 0.5 * i}, clock_ns=i * 10**9
            )
            log.log_camera(CAM, INTR, T)
            log.log_depth(DEPTH, scene_depth(i, bump))
            mask = np.zeros((H, W), np.uint8)
            mask[1:3, 1:4] = 1
            mask[3:5, 4:7] = 2
            log.log_segmentation(SEG, mask)
            n = 0 if i == EMPTY_SCENE else 2
            centers = np.array([[0.1, 0.0, 0.1], [-0.1, 0.05, 0.12]])[:n]
            sizes = np.array([[0.05, 0.04, 0.02], [0.06, 0.03, 0.02]])[:n]
            quats = np.array([[0, 0, 0, 1.0], [0, 0, np.sin(0.3), np.cos(0.3)]])[:n]
            log.log_boxes(BOXES, centers, sizes, quats, labels=[f"box{k}" for k in range(n)])
            log.log_scalar(SCALAR, 0.25 * i)
            log.log_text(TEXT, f"scene {i}: {n} boxes", level="WARN" if n == 0 else "INFO")


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("stage_logs")
    out = {"a": root / "a", "b": root / "b", "changed": root / "changed"}
    write_log(out["a"])
    write_log(out["b"])
    write_log(out["changed"], bump=0.125)
    return out


def test_files_exist(logs):
    for folder in logs.values():
        assert (folder / "log.rrd").stat().st_size > 0
        assert (folder / "log.mcap").stat().st_size > 0
    res = subprocess.run(
        [rerun_executable(), "rrd", "verify", str(logs["a"] / "log.rrd")],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_rrd_entity_paths_and_recording_id(logs):
    paths = rrd_entity_paths(logs["a"] / "log.rrd")
    expected = {f"/{e}" for e in (CAM, DEPTH, SEG, BOXES, BIN, SCALAR, TEXT)}
    assert expected <= paths, expected - paths
    assert rrd_recording_id(logs["a"] / "log.rrd") == "rec-0001"


def test_rrd_has_no_wall_clock_data(logs):
    path = logs["a"] / "log.rrd"
    assert rrd_timelines(path) == {"scene", "sim_time"}  # no log_time / log_tick
    from rerun.chunk import RrdReader

    chunks = list(RrdReader(path).stream().collect().stream())
    props = [c for c in chunks if c.entity_path == "/__properties"]
    cols = {n for c in props for n in c.to_record_batch().schema.names}
    assert "RecordingInfo:name" in cols and not any("start_time" in n for n in cols)
    # the scene with 0 boxes really clears them (empty batches), the bin is static
    (boxes,) = [c for c in chunks if c.entity_path == f"/{BOXES}"]
    centers = boxes.to_record_batch().column("Boxes3D:centers").to_pylist()
    assert [len(x) for x in centers] == [0 if i == EMPTY_SCENE else 2 for i in range(N_SCENES)]
    labels = boxes.to_record_batch().column("Boxes3D:labels").to_pylist()
    assert labels[EMPTY_SCENE] == []
    assert all(c.is_static for c in chunks if c.entity_path == f"/{BIN}")


def test_mcap_message_counts(logs):
    counts = mcap_message_counts(logs["a"] / "log.mcap")
    n = N_SCENES
    assert counts == {
        "/tf": n,
        f"/{CAM}/calibration": n,
        f"/{DEPTH}": n,
        f"/{SEG}": n,
        f"/{BOXES}": n,
        f"/{BIN}": 1,
        f"/{SCALAR}": n,
        f"/{TEXT}": n,
    }


def test_mcap_check_cli(logs):
    exe = rerun_executable()
    probe = subprocess.run([exe, "mcap", "check", "--help"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip("this rerun CLI has no `mcap check`")
    res = subprocess.run(
        [exe, "mcap", "check", str(logs["a"] / "log.mcap")], capture_output=True, text=True
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_reproducible(logs):
    assert (logs["a"] / "log.mcap").read_bytes() == (logs["b"] / "log.mcap").read_bytes()
    assert rrd_equal(logs["a"] / "log.rrd", logs["b"] / "log.rrd")


def test_changed_depth_detected(logs):
    assert not rrd_equal(logs["a"] / "log.rrd", logs["changed"] / "log.rrd")
    assert (logs["a"] / "log.mcap").read_bytes() != (logs["changed"] / "log.mcap").read_bytes()


def _decoded(path: Path, topic: str) -> list:
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [(ch, msg, dec) for _, ch, msg, dec in reader.iter_decoded_messages(topics=[topic])]


def test_mcap_depth_round_trip(logs):
    msgs = _decoded(logs["a"] / "log.mcap", f"/{DEPTH}")
    assert len(msgs) == N_SCENES
    for i, (ch, msg, img) in enumerate(msgs):
        assert ch.message_encoding == "protobuf"
        assert msg.log_time == msg.publish_time == i * 10**9
        assert (img.timestamp.seconds, img.timestamp.nanos) == (i, 0)
        assert (img.width, img.height, img.encoding, img.step) == (W, H, "32FC1", 4 * W)
        assert img.frame_id == "camera"
        back = np.frombuffer(img.data, dtype="<f4").reshape(img.height, img.width)
        np.testing.assert_array_equal(back, scene_depth(i))


def test_mcap_boxes_camera_scalar_text(logs):
    path = logs["a"] / "log.mcap"
    boxes = _decoded(path, f"/{BOXES}")
    assert [len(u.entities) for _, _, u in boxes] == [1] * N_SCENES
    assert [len(u.entities[0].cubes) for _, _, u in boxes] == [
        0 if i == EMPTY_SCENE else 2 for i in range(N_SCENES)
    ]
    cube = boxes[0][2].entities[0].cubes[1]
    assert cube.size.x == pytest.approx(0.06) and cube.pose.orientation.w == pytest.approx(
        np.cos(0.3)
    )
    assert boxes[0][2].entities[0].id == BOXES and boxes[0][2].entities[0].frame_id == "world"

    (_, msg, calib), *_ = _decoded(path, f"/{CAM}/calibration")
    assert list(calib.K) == [10.0, 0.0, 3.5, 0.0, 11.0, 2.5, 0.0, 0.0, 1.0]
    assert list(calib.P) == [10.0, 0.0, 3.5, 0.0, 0.0, 11.0, 2.5, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert (calib.width, calib.height, calib.frame_id) == (W, H, "camera")
    (_, _, tf), *_ = _decoded(path, "/tf")
    assert (tf.parent_frame_id, tf.child_frame_id) == ("world", "camera")
    assert tf.translation.z == pytest.approx(1.2)
    assert (tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w) == pytest.approx(
        (1, 0, 0, 0)
    )

    # JSON channel: mcap 1.6 has no JSON decoder, so read raw messages.
    import json

    with open(path, "rb") as f:
        reader = make_reader(f)
        raw = [(s, c, m) for s, c, m in reader.iter_messages(topics=[f"/{SCALAR}"])]
    assert [json.loads(m.data) for _, _, m in raw] == [{"value": 0.25 * i} for i in range(N_SCENES)]
    assert raw[0][0].encoding == "jsonschema" and raw[0][1].message_encoding == "json"

    logs_ = _decoded(path, f"/{TEXT}")
    assert [d.message for _, _, d in logs_] == [
        f"scene {i}: {0 if i == EMPTY_SCENE else 2} boxes" for i in range(N_SCENES)
    ]


def test_points_and_several_open_logs(tmp_path):
    """Two StageLogs open at once (separate foxglove Contexts) do not mix their channels."""
    pts = np.arange(12, dtype=np.float32).reshape(4, 3) / 10
    with StageLog(tmp_path / "p", "t", "p") as lp, StageLog(tmp_path / "q", "t", "q") as lq:
        lp.set_time(sequences={"scene": 0}, clock_ns=5)
        lq.set_time(sequences={"scene": 0}, clock_ns=7)
        lp.log_points("world/points", pts)
        lq.log_points("world/points", pts, colors=np.full((4, 3), 200, np.uint8))
        lq.log_scalar("metrics/x", 1.0)
        lp.close()  # idempotent with the context manager's close
    assert mcap_message_counts(tmp_path / "p" / "log.mcap") == {"/world/points": 1}
    assert mcap_message_counts(tmp_path / "q" / "log.mcap") == {"/world/points": 1, "/metrics/x": 1}
    ((_, msg, cloud),) = _decoded(tmp_path / "p" / "log.mcap", "/world/points")
    assert (
        msg.log_time == 5
        and cloud.point_stride == 12
        and [f.name for f in cloud.fields] == ["x", "y", "z"]
    )
    np.testing.assert_array_equal(np.frombuffer(cloud.data, "<f4").reshape(-1, 3), pts)
    ((_, _, cloud),) = _decoded(tmp_path / "q" / "log.mcap", "/world/points")
    assert cloud.point_stride == 16 and len(cloud.fields) == 7
    assert "/world/points" in rrd_entity_paths(tmp_path / "q" / "log.rrd")


def test_helpers():
    assert topic_for("world/camera/depth") == "/world/camera/depth"
    assert topic_for("/a/b") == "/a/b"
    assert isinstance(default_blueprint(), rrb.Blueprint)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    assert quat_xyzw_from_matrix(R) == pytest.approx((0, 0, np.sqrt(0.5), np.sqrt(0.5)))
    assert quat_xyzw_from_matrix(np.diag([1.0, -1.0, -1.0])) == pytest.approx((1, 0, 0, 0))
