"""Lock-step, reproducible stage logs: one Rerun ``.rrd`` and one Foxglove ``.mcap`` per stage.

A :class:`StageLog` writes every call to both ``<folder>/log.rrd`` (Rerun, rerun-sdk 0.41) and
``<folder>/log.mcap`` (Foxglove well-known protobuf messages written by foxglove-sdk, so the file
opens in Foxglove with no schema work).

Reproducibility: nothing here reads the wall clock.

* Rerun: the automatic ``log_time`` timeline is switched off (``set_log_time_enabled(False)``;
  ``log_tick`` is off by default), the default recording properties (which carry a wall-clock
  ``RecordingInfo:start_time``) are not sent (only the recording name, = ``recording_id``), and
  data are indexed only by the timelines the caller sets with
  :meth:`StageLog.set_time`. Two runs with the same calls give ``rerun rrd compare`` exit 0 (the
  .rrd bytes themselves are not identical between runs).
* MCAP: every message is written with an explicit ``log_time`` (= publish time) and every message
  header ``timestamp`` is set from the same caller-supplied clock, the writer uses single-threaded
  zstd, so two runs give byte-identical files.

What still differs between two runs of the .rrd (all ignored by ``rerun rrd compare``): chunk and
row ids (time-based TUIDs) and, when a blueprint is sent, the blueprint store (its own random
store id, random view/container ids, and a ``log_time`` column, since Rerun creates that stream
internally with default settings).

Conventions used throughout:

* Entity paths are Rerun paths such as ``"world/camera/depth"``; the MCAP topic is the same path
  with a leading slash (``"/world/camera/depth"``).
* Lengths are metres, images are row-major ``(H, W)`` arrays, poses are 4x4 homogeneous matrices
  ``T_parent_child`` mapping child-frame points into the parent frame.
* Cameras use the OpenCV convention (x right, y down, z forward; Rerun ``ViewCoordinates.RDF``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import foxglove
import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from foxglove import channels as fxc
from foxglove import messages as fxm
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from pipeline.camera.geometry import quat_from_matrix

__all__ = ["StageLog", "default_blueprint", "quat_xyzw_from_matrix", "topic_for"]

RRD_NAME = "log.rrd"
MCAP_NAME = "log.mcap"
#: Rerun application id of a pipeline stage's log: this prefix and the stage's name.
APP_ID_PREFIX = "binpick-"

#: JSON schema of the scalar channels written by :meth:`StageLog.log_scalar`.
SCALAR_JSON_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "Scalar",
    "properties": {"value": {"type": "number"}},
    "required": ["value"],
}

# Level names accepted by log_text -> (Rerun TextLogLevel string, Foxglove LogLevel).
_LEVELS: dict[str, tuple[str, Any]] = {
    "TRACE": ("TRACE", fxm.LogLevel.Debug),
    "DEBUG": ("DEBUG", fxm.LogLevel.Debug),
    "INFO": ("INFO", fxm.LogLevel.Info),
    "WARN": ("WARN", fxm.LogLevel.Warning),
    "WARNING": ("WARN", fxm.LogLevel.Warning),
    "ERROR": ("ERROR", fxm.LogLevel.Error),
    "CRITICAL": ("CRITICAL", fxm.LogLevel.Fatal),
    "FATAL": ("CRITICAL", fxm.LogLevel.Fatal),
}


def topic_for(entity: str) -> str:
    """MCAP topic of a Rerun entity path: ``"world/camera/depth"`` -> ``"/world/camera/depth"``."""
    e = entity.strip("/")
    if not e:
        raise ValueError("entity path must not be empty")
    return "/" + e


def _mcap_write_options() -> MCAPWriteOptions:
    # Single-threaded zstd and a fixed chunk size: output depends only on the logged messages.
    return MCAPWriteOptions(
        compression=MCAPCompression.Zstd,
        chunk_size=1 << 20,
        compression_level=0,
        compression_threads=0,
    )


def _timestamp(clock_ns: int) -> fxm.Timestamp:
    sec, nsec = divmod(int(clock_ns), 1_000_000_000)
    return fxm.Timestamp(sec, nsec)


def quat_xyzw_from_matrix(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) with w >= 0 of a 3x3 rotation matrix."""
    q = quat_from_matrix(R)
    if q[3] < 0:
        q = -q
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def _as_colors_u8(colors: np.ndarray, n: int) -> np.ndarray:
    """(N,3)/(N,4) uint8 or float in [0,1] -> (N,4) uint8 RGBA."""
    c = np.asarray(colors)
    if c.ndim != 2 or c.shape[0] != n or c.shape[1] not in (3, 4):
        raise ValueError(f"colors must have shape ({n}, 3) or ({n}, 4), got {c.shape}")
    if c.dtype != np.uint8:
        c = np.clip(np.rint(np.asarray(c, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)
    if c.shape[1] == 3:
        c = np.concatenate([c, np.full((n, 1), 255, dtype=np.uint8)], axis=1)
    return np.ascontiguousarray(c)


class StageLog:
    """Write one stage's log to ``<folder>/log.rrd`` and ``<folder>/log.mcap`` in lock-step.

    Parameters
    ----------
    folder:
        Output folder (created if missing). Existing ``log.rrd`` / ``log.mcap`` are overwritten.
    app_id:
        Rerun application id (the viewer groups recordings and blueprints by it).
    recording_id:
        Rerun recording id; fix it (e.g. from the stage's artifact key) for reproducible logs.
    blueprint:
        Optional Rerun blueprint sent right after opening the file (see :func:`default_blueprint`);
        it becomes the default and active layout for ``app_id``.

    Time: call :meth:`set_time` before logging a step. Until the first call the Rerun data carry
    no timeline (i.e. they are timeless-at-"no time" rather than static) and MCAP messages get
    ``log_time = 0``.

    Each instance owns its own ``foxglove.Context`` and ``rr.RecordingStream``, so several
    ``StageLog`` objects may be open in one process. Use as a context manager or call
    :meth:`close`. Not thread-safe.
    """

    def __init__(
        self, folder: Path, app_id: str, recording_id: str, blueprint: rrb.Blueprint | None = None
    ) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.rrd_path = self.folder / RRD_NAME
        self.mcap_path = self.folder / MCAP_NAME
        self.app_id = app_id
        self.recording_id = recording_id
        self._clock_ns = 0
        self._closed = False

        # --- Rerun -------------------------------------------------------------------------
        # send_properties=False: the default properties hold RecordingInfo:start_time, the
        # wall-clock time of creation (which `rerun rrd compare` does not even flag).
        self.rec = rr.RecordingStream(app_id, recording_id=recording_id, send_properties=False)
        self.rec.set_log_time_enabled(False)  # no wall-clock `log_time` timeline
        self.rec.set_log_tick_enabled(False)  # off by default; RERUN_LOG_TICK could turn it on
        self.rec.save(str(self.rrd_path))
        self.rec.send_recording_name(recording_id)
        if blueprint is not None:
            self.rec.send_blueprint(blueprint)

        # --- MCAP --------------------------------------------------------------------------
        self.ctx = foxglove.Context()
        self._writer = foxglove.open_mcap(
            self.mcap_path,
            allow_overwrite=True,
            context=self.ctx,
            writer_options=_mcap_write_options(),
        )
        self._channels: dict[str, Any] = {}

    @classmethod
    def for_stage(
        cls, folder: Path, stage: str, recording_id: str, blueprint: rrb.Blueprint | None = None
    ) -> StageLog:
        """The log of a pipeline stage's artifact: app id ``binpick-<stage>`` (one viewer group
        per stage), ``recording_id`` its version key; in ``folder``, its work folder."""
        return cls(
            folder, app_id=APP_ID_PREFIX + stage, recording_id=recording_id, blueprint=blueprint
        )

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> StageLog:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        self.close()

    def close(self) -> None:
        """Flush and close both files. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.close()
        finally:
            self.rec.flush()
            self.rec.disconnect()

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"StageLog for {self.folder} is closed")

    # ------------------------------------------------------------------ time
    def set_time(
        self,
        *,
        sequences: dict[str, int] | None = None,
        durations_s: dict[str, float] | None = None,
        clock_ns: int,
    ) -> None:
        """Set the time for all following log calls.

        Rerun: each ``sequences`` entry sets an integer sequence timeline
        (``rec.set_time(name, sequence=...)``) and each ``durations_s`` entry a duration timeline
        in seconds (``rec.set_time(name, duration=...)``).

        MCAP: every following message gets ``log_time = publish_time = clock_ns`` (int
        nanoseconds, >= 0) and the same value as its header ``timestamp``. The caller must derive
        ``clock_ns`` deterministically (e.g. ``scene_index * 10**9``), never from the wall clock.
        """
        self._check_open()
        clock_ns = int(clock_ns)
        if clock_ns < 0:
            raise ValueError("clock_ns must be >= 0")
        for name, value in (sequences or {}).items():
            self.rec.set_time(name, sequence=int(value))
        for name, value in (durations_s or {}).items():
            self.rec.set_time(name, duration=float(value))
        self._clock_ns = clock_ns

    # ------------------------------------------------------------------ MCAP plumbing
    def _channel(self, topic: str, cls: Any) -> Any:
        ch = self._channels.get(topic)
        if ch is None:
            if cls is foxglove.Channel:
                ch = foxglove.Channel(topic, schema=SCALAR_JSON_SCHEMA, context=self.ctx)
            else:
                ch = cls(topic, context=self.ctx)
            self._channels[topic] = ch
        elif not isinstance(ch, cls):
            raise TypeError(
                f"topic {topic} already carries {type(ch).__name__}, not {cls.__name__}"
            )
        return ch

    def _mcap_log(self, topic: str, cls: Any, msg: Any, log_time: int | None = None) -> None:
        self._channel(topic, cls).log(
            msg, log_time=self._clock_ns if log_time is None else log_time
        )

    def _mcap_image(self, entity: str, image: np.ndarray, encoding: str, frame_id: str) -> None:
        """A ``RawImage`` of ``image`` (``(H, W)``, C-contiguous, in the byte order ``encoding``
        names) on ``/{entity}``: ``step`` = W × its item size, ``data`` its bytes."""
        h, w = image.shape
        img = fxm.RawImage(
            timestamp=_timestamp(self._clock_ns),
            frame_id=frame_id,
            width=w,
            height=h,
            encoding=encoding,
            step=w * image.itemsize,
            data=image.tobytes(),
        )
        self._mcap_log(topic_for(entity), fxc.RawImageChannel, img)

    # ------------------------------------------------------------------ camera
    def log_camera(
        self, entity: str, intrinsics: Any, T_world_cam: np.ndarray, frame_id: str = "camera"
    ) -> None:
        """Log a pinhole depth camera's pose and intrinsics.

        ``intrinsics`` has attributes ``width``, ``height`` (int pixels) and ``fx``, ``fy``,
        ``cx``, ``cy`` (float pixels), e.g. :class:`pipeline.camera.Intrinsics`.
        ``T_world_cam`` is a 4x4 float pose mapping camera-frame points (metres, OpenCV
        convention: x right, y down, z forward) into the world frame.

        Rerun: ``Transform3D`` (translation + 3x3 matrix; all other transform components are
        cleared, since 0.28 every update must re-log every component) and ``Pinhole``
        (``camera_xyz=RDF``, ``resolution=[W, H]``, ``image_from_camera=K``) at ``entity``.
        Images logged below ``entity`` are shown in the camera's image plane.

        MCAP: a ``FrameTransform`` ``world -> frame_id`` on ``/tf`` and a ``CameraCalibration``
        (``K`` 3x3 and ``P`` 3x4 row-major, ``R`` = identity, zero plumb_bob distortion) on
        ``/{entity}/calibration`` with ``frame_id``.
        """
        self._check_open()
        T = np.asarray(T_world_cam, dtype=np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"T_world_cam must be 4x4, got {T.shape}")
        w, h = int(intrinsics.width), int(intrinsics.height)
        fx, fy = float(intrinsics.fx), float(intrinsics.fy)
        cx, cy = float(intrinsics.cx), float(intrinsics.cy)
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        t = T[:3, 3]
        R = T[:3, :3]

        self.rec.log(
            entity,
            rr.Transform3D.from_fields(clear_unset=True, translation=t, mat3x3=R),
            rr.Pinhole.from_fields(
                clear_unset=True,
                image_from_camera=K,
                resolution=[w, h],
                camera_xyz=rr.ViewCoordinates.RDF,
            ),
        )

        ts = _timestamp(self._clock_ns)
        qx, qy, qz, qw = quat_xyzw_from_matrix(R)
        tf = fxm.FrameTransform(
            timestamp=ts,
            parent_frame_id="world",
            child_frame_id=frame_id,
            translation=fxm.Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
            rotation=fxm.Quaternion(x=qx, y=qy, z=qz, w=qw),
        )
        self._mcap_log("/tf", fxc.FrameTransformChannel, tf)
        P = np.concatenate([K, np.zeros((3, 1))], axis=1)
        calib = fxm.CameraCalibration(
            timestamp=ts,
            frame_id=frame_id,
            width=w,
            height=h,
            distortion_model="plumb_bob",
            D=[0.0] * 5,
            K=[float(v) for v in K.ravel()],
            R=[float(v) for v in np.eye(3).ravel()],
            P=[float(v) for v in P.ravel()],
        )
        self._mcap_log(topic_for(entity) + "/calibration", fxc.CameraCalibrationChannel, calib)

    # ------------------------------------------------------------------ images
    def log_depth(self, entity: str, depth_m: np.ndarray, frame_id: str = "camera") -> None:
        """Log a depth image.

        ``depth_m``: ``(H, W)`` float32 metres along the camera z axis, 0 = no data.

        Rerun: ``rr.DepthImage(depth, meter=1.0)`` at ``entity``.
        MCAP: ``RawImage`` with encoding ``32FC1``, little-endian float32, ``step = 4 W``,
        on ``/{entity}``.
        """
        self._check_open()
        d = np.asarray(depth_m)
        if d.ndim != 2:
            raise ValueError(f"depth must be (H, W), got {d.shape}")
        d = np.ascontiguousarray(d, dtype=np.float32)
        self.rec.log(entity, rr.DepthImage(d, meter=1.0))
        self._mcap_image(entity, d.astype("<f4", copy=False), "32FC1", frame_id)

    def log_segmentation(self, entity: str, mask: np.ndarray, frame_id: str = "camera") -> None:
        """Log an instance segmentation mask.

        ``mask``: ``(H, W)`` uint8 instance ids, 0 = background.

        Rerun: ``rr.SegmentationImage`` at ``entity`` (ids are class ids for the viewer's colours).
        MCAP: ``RawImage`` with encoding ``mono8``, ``step = W``, on ``/{entity}``.
        """
        self._check_open()
        m = np.asarray(mask)
        if m.ndim != 2:
            raise ValueError(f"mask must be (H, W), got {m.shape}")
        if m.dtype != np.uint8:
            if m.size and (m.min() < 0 or m.max() > 255):
                raise ValueError("mask ids must fit in uint8")
            m = m.astype(np.uint8)
        m = np.ascontiguousarray(m)
        self.rec.log(entity, rr.SegmentationImage(m))
        self._mcap_image(entity, m, "mono8", frame_id)

    # ------------------------------------------------------------------ geometry
    @staticmethod
    def _check_boxes(
        centers: np.ndarray, sizes: np.ndarray, quats_xyzw: np.ndarray, labels: list[str] | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
        s = np.asarray(sizes, dtype=np.float64).reshape(-1, 3)
        q = np.asarray(quats_xyzw, dtype=np.float64).reshape(-1, 4)
        n = c.shape[0]
        if s.shape[0] != n or q.shape[0] != n:
            raise ValueError(
                f"centers, sizes, quats_xyzw disagree on N: {c.shape}, {s.shape}, {q.shape}"
            )
        if labels is not None and len(labels) != n:
            raise ValueError(f"{len(labels)} labels for {n} boxes")
        return c, s, q, n

    def log_boxes(
        self,
        entity: str,
        centers: np.ndarray,
        sizes: np.ndarray,
        quats_xyzw: np.ndarray,
        labels: list[str] | None = None,
        frame_id: str = "world",
        *,
        static: bool = False,
    ) -> None:
        """Log N oriented boxes in ``frame_id`` (``entity`` should live under that frame in Rerun).

        ``centers``: ``(N, 3)`` metres; ``sizes``: ``(N, 3)`` full edge lengths in metres;
        ``quats_xyzw``: ``(N, 4)`` unit quaternions (x, y, z, w) rotating box into frame;
        ``labels``: N strings or None. N may be 0 (the previous boxes then disappear).
        ``static``: fixed geometry (e.g. the bin walls): Rerun ``static=True``, MCAP
        ``log_time = 0``; log it before the first timed message so the MCAP stays in time order.

        Rerun: ``Boxes3D`` (centers, half_sizes = sizes / 2, quaternions, labels, class_ids
        ``1..N`` in order) with every other component cleared.
        MCAP: one ``SceneUpdate`` on ``/{entity}`` holding one ``SceneEntity`` (``id = entity``,
        infinite lifetime, replacing the previous one) with N ``CubePrimitive`` and the labels
        as ``label_<i>`` metadata.
        """
        self._check_open()
        c, s, q, n = self._check_boxes(centers, sizes, quats_xyzw, labels)
        # clear_unset: components not given now (e.g. labels) must not linger from a previous
        # scene; with N = 0 every component is an empty batch, so the boxes disappear.
        self.rec.log(
            entity,
            rr.Boxes3D.from_fields(
                clear_unset=True,
                centers=c.astype(np.float32),
                half_sizes=(0.5 * s).astype(np.float32),
                quaternions=q.astype(np.float32),
                labels=list(labels) if labels is not None else None,
                class_ids=np.arange(1, n + 1, dtype=np.uint16),
            ),
            static=static,
        )
        clock = 0 if static else self._clock_ns
        cubes = [
            fxm.CubePrimitive(
                pose=fxm.Pose(
                    position=fxm.Vector3(x=float(c[i, 0]), y=float(c[i, 1]), z=float(c[i, 2])),
                    orientation=fxm.Quaternion(
                        x=float(q[i, 0]), y=float(q[i, 1]), z=float(q[i, 2]), w=float(q[i, 3])
                    ),
                ),
                size=fxm.Vector3(x=float(s[i, 0]), y=float(s[i, 1]), z=float(s[i, 2])),
                color=fxm.Color(r=0.2, g=0.6, b=1.0, a=0.5),
            )
            for i in range(n)
        ]
        entity_msg = fxm.SceneEntity(
            timestamp=_timestamp(clock),
            frame_id=frame_id,
            id=entity,
            cubes=cubes,
            metadata=(
                [fxm.KeyValuePair(key=f"label_{i}", value=str(lbl)) for i, lbl in enumerate(labels)]
                if labels is not None
                else None
            ),
        )
        self._mcap_log(
            topic_for(entity),
            fxc.SceneUpdateChannel,
            fxm.SceneUpdate(entities=[entity_msg]),
            log_time=clock,
        )

    def log_points(
        self,
        entity: str,
        points: np.ndarray,
        colors: np.ndarray | None = None,
        frame_id: str = "camera",
    ) -> None:
        """Log a point cloud.

        ``points``: ``(N, 3)`` float32 metres in ``frame_id``; ``colors``: optional ``(N, 3)``
        or ``(N, 4)`` uint8 RGB(A) (floats in [0, 1] are scaled to uint8).

        Rerun: ``Points3D`` (positions, colors) at ``entity``.
        MCAP: ``PointCloud`` on ``/{entity}`` with float32 fields ``x, y, z`` at offsets 0, 4, 8
        (stride 12), plus uint8 ``red, green, blue, alpha`` at 12..15 (stride 16) with colours.
        """
        self._check_open()
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
        n = p.shape[0]
        F = fxm.PackedElementFieldNumericType
        fields = [
            fxm.PackedElementField(name="x", offset=0, type=F.Float32),
            fxm.PackedElementField(name="y", offset=4, type=F.Float32),
            fxm.PackedElementField(name="z", offset=8, type=F.Float32),
        ]
        if colors is None:
            self.rec.log(entity, rr.Points3D.from_fields(clear_unset=True, positions=p))
            stride = 12
            data = p.astype("<f4", copy=False).tobytes()
        else:
            rgba = _as_colors_u8(colors, n)
            self.rec.log(
                entity, rr.Points3D.from_fields(clear_unset=True, positions=p, colors=rgba)
            )
            stride = 16
            rec = np.zeros(n, dtype=[("xyz", "<f4", (3,)), ("rgba", "u1", (4,))])
            rec["xyz"] = p
            rec["rgba"] = rgba
            data = rec.tobytes()
            fields += [
                fxm.PackedElementField(name=nm, offset=12 + k, type=F.Uint8)
                for k, nm in enumerate(("red", "green", "blue", "alpha"))
            ]
        cloud = fxm.PointCloud(
            timestamp=_timestamp(self._clock_ns),
            frame_id=frame_id,
            pose=fxm.Pose(position=fxm.Vector3(), orientation=fxm.Quaternion(w=1.0)),
            point_stride=stride,
            fields=fields,
            data=data,
        )
        self._mcap_log(topic_for(entity), fxc.PointCloudChannel, cloud)

    # ------------------------------------------------------------------ scalars and text
    def log_scalar(self, entity: str, value: float) -> None:
        """Log one float64 value (e.g. ``metrics/iou``).

        Rerun: ``rr.Scalars(value)`` at ``entity`` (plot with a time-series view).
        MCAP: JSON message ``{"value": value}`` on ``/{entity}``, a ``json`` channel whose
        ``jsonschema`` schema is :data:`SCALAR_JSON_SCHEMA` (plot ``/{entity}.value`` in Foxglove).
        """
        self._check_open()
        v = float(value)
        self.rec.log(entity, rr.Scalars(v))
        self._mcap_log(topic_for(entity), foxglove.Channel, {"value": v})

    def log_text(self, entity: str, text: str, level: str = "INFO") -> None:
        """Log a text line with a level in TRACE, DEBUG, INFO, WARN(ING), ERROR, CRITICAL/FATAL.

        Rerun: ``rr.TextLog(text, level=...)`` at ``entity``.
        MCAP: foxglove ``Log`` (``name = entity``) on ``/{entity}``.
        """
        self._check_open()
        try:
            rr_level, fx_level = _LEVELS[level.upper()]
        except KeyError:
            raise ValueError(f"unknown log level {level!r}; use one of {sorted(_LEVELS)}") from None
        self.rec.log(entity, rr.TextLog(text, level=rr_level))
        msg = fxm.Log(
            timestamp=_timestamp(self._clock_ns), level=fx_level, message=text, name=entity
        )
        self._mcap_log(topic_for(entity), fxc.LogChannel, msg)


# ---------------------------------------------------------------------- blueprint
def default_blueprint(camera_entity: str = "world/camera") -> rrb.Blueprint:
    """Viewer layout: 3D view of ``world`` | 2D view of the camera (its depth and segmentation
    images, children of ``camera_entity``) over a text-log view and a time-series view of
    ``metrics``."""
    cam = camera_entity.strip("/")
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="scene", origin="world"),
            rrb.Vertical(
                rrb.Spatial2DView(name="camera", origin=cam, contents=["$origin/**"]),
                rrb.Horizontal(
                    rrb.TextLogView(name="log"),
                    rrb.TimeSeriesView(name="metrics", origin="metrics"),
                ),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
