"""The robot's motions: the 2.5D visual servo (paper Sec. 5, Fig. 2's blue loop) and the
open-loop moves around it, as joint commands computed with the robot's own kinematic model.

**Servo** (:class:`Servo`): every control period (``servo.control_rate_hz``) a new observation →
the surface feature descriptor seeded at the previous g′ (G_opt at first; the previous g′ is
carried into the new image by the camera's own motion, forward kinematics, since the image
moves tens of pixels between frames) → features → the 2.5D visual-servoing law (Eq. 23) →
joint velocities through the damped pseudo-inverse of the camera Jacobian (Eq. 28), limited to
``motion.max_joint_speed`` → the joint command for the next period. It starts towards the
approach's first goal (``motion.approach``) and, there, goes on to d*. For a single suction
point (Dex-Net's kind) the servo target is that point, fixed in the world (the descriptor
supplies the surface normal and axes), not the surface centre: Dex-Net does not refine its
point. While tracking, the descriptor stays on the tracked surface: the previous frame's normal
and plane, carried by the camera's motion (``servo.track_normal_deg``,
``servo.track_offset_m``).

**Moves** (:class:`Mover`): the approach along the camera axis from d* until the lips touch and
press (``motion.press_depth``), the lift straight up by ``motion.lift_height``, the joints of
the conveyor pose, the duration of a point-to-point move (:func:`move_time`).

Frames: camera (OpenCV) for features and twists; world (z up) for poses. Joint vectors (7,),
radians; metres, seconds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from pipeline.camera.geometry import world_to_camera
from pipeline.controller.observation import Observation
from pipeline.robot.model import Robot
from pipeline.robot.urdf_builder import CUP_TIP_Z


def move_time(dq: np.ndarray, max_speed: float, max_accel: float) -> float:
    """Duration (s) of a synchronised point-to-point move: the slowest joint's trapezoidal
    (or triangular, for short moves) profile at ``max_speed`` (rad/s) and ``max_accel``."""
    d = float(np.max(np.abs(dq))) if len(dq) else 0.0
    if d <= 0.0:
        return 0.0
    if d >= max_speed**2 / max_accel:
        return d / max_speed + max_speed / max_accel
    return 2.0 * math.sqrt(d / max_accel)


def project(T_world_cam: np.ndarray, point_world: np.ndarray, intr, fallback) -> np.ndarray:
    """Pixel (u, v) of a world point in a camera; ``fallback`` when it is behind the camera."""
    c = world_to_camera(np.asarray(point_world, np.float64)[None], T_world_cam)[0]
    if c[2] <= 1e-6:
        return np.asarray(fallback, np.float64)
    return np.array([intr.fx * c[0] / c[2] + intr.cx, intr.fy * c[1] / c[2] + intr.cy])


class Kinematics:
    """The robot's joint update from a camera twist, on its own robot model."""

    def __init__(self, cfg, robot: Robot) -> None:
        self.robot = robot
        self.dt = 1.0 / float(cfg.servo.control_rate_hz)
        self.damping = float(cfg.servo.joint_damping)
        self.max_speed = float(cfg.motion.max_joint_speed)

    def step(self, q: np.ndarray, twist_cam: np.ndarray) -> tuple[np.ndarray, bool]:
        """(the joints after one control period of ``twist_cam`` (6,), camera frame, from
        ``q``; whether the speed limit or a joint limit clamped the step)."""
        from pipeline.servo.jacobian import camera_jacobian, integrate, joint_velocities

        J = camera_jacobian(self.robot, q)
        qdot = joint_velocities(J, twist_cam, self.damping)
        return integrate(self.robot, q, qdot, self.dt, self.max_speed)


@dataclass
class ServoStep:
    """What one control period decided.

    Attributes:
        status: "move" (``q`` is the next command), "converged", "lost" (``reason``: the
            descriptor's, or "behind_camera" for a fixed point).
        q: (7,) the joint command for the next period ("move").
        clamped: the step was clamped by a speed or joint limit.
        feats: the descriptor's surface in this frame (None when lost).
        cmd: the control law's output (``pipeline.servo.control.ServoCommand``).
        g_px: (2,) g′ in this image.
    """

    status: str
    q: np.ndarray | None = None
    clamped: bool = False
    feats: object = None
    cmd: object = None
    reason: str = ""
    g_px: np.ndarray = field(default_factory=lambda: np.zeros(2))


class Servo:
    """One attempt's visual servo (module docstring)."""

    def __init__(
        self,
        cfg,
        kin: Kinematics,
        descriptor_cfg,
        servo_cfg,
        plan,
        perceive=None,
        timings: dict | None = None,
    ) -> None:
        """``plan``: the ``pipeline.controller.picker.Plan`` to execute; ``perceive``: the
        depth preprocessing applied to every observation (None: none); ``timings``: lists
        ``descriptor_s`` and ``control_law_s`` (the law and the joint update) get each step's
        wall times."""
        self.cfg, self.kin, self.descriptor_cfg = cfg, kin, descriptor_cfg
        self.perceive = perceive or (lambda obs: obs)
        self.timings = timings if timings is not None else {"descriptor_s": [], "control_law_s": []}
        self.final_cfg = servo_cfg  # d*
        self.servo_cfg = servo_cfg  # the approach's first goal, then d* (step 0 sets it)
        self.plan = plan
        self.seed = np.array([plan.grasp.u, plan.grasp.v], np.float64)
        self.normal_world = None  # the tracked surface's normal (world), from the last frame
        self.g_world = None  # and its centre g′ (world)
        self.fixed_world = plan.fixed_point_world  # Dex-Net's point, or None
        self.step_index = 0
        self.pregrasp_standoff = 0.0

    def step(self, obs: Observation) -> ServoStep:
        """One control period on ``obs`` (the first is the plan's home observation)."""
        from pipeline.robot.approach import first_goal
        from pipeline.servo.control import servo_velocity
        from pipeline.servo.descriptor import describe_surface

        obs = self.perceive(obs)
        plan, intr, T = self.plan, obs.intrinsics, obs.T_world_cam
        expected = None if self.normal_world is None else T[:3, :3].T @ self.normal_world
        on_plane = None if self.g_world is None else world_to_camera(self.g_world[None], T)[0]
        sites = None if plan.sites_world is None else world_to_camera(plan.sites_world, T)
        t0 = time.perf_counter()
        feats, reason = describe_surface(
            obs.depth_m,
            intr,
            self.seed,
            self.descriptor_cfg,
            expected_normal_cam=expected,
            sites_cam=sites,
            expected_point_cam=on_plane,
        )
        t1 = time.perf_counter()
        self.timings["descriptor_s"].append(t1 - t0)
        if feats is None:
            return ServoStep("lost", reason=str(reason))
        T_cam_world = np.linalg.inv(T)
        if self.fixed_world is not None:
            centre = T_cam_world[:3, :3] @ self.fixed_world + T_cam_world[:3, 3]
            if centre[2] <= 1e-3:
                return ServoStep("lost", feats=feats, reason="behind_camera")
            self.seed = np.array(
                [
                    intr.fx * centre[0] / centre[2] + intr.cx,
                    intr.fy * centre[1] / centre[2] + intr.cy,
                ]
            )
        else:
            centre = feats.center_cam
        self.g_world = T[:3, :3] @ np.asarray(feats.center_cam) + T[:3, 3]
        self.normal_world = T[:3, :3] @ np.asarray(feats.normal_cam)
        ref = None if plan.x_world is None else T_cam_world[:3, :3] @ plan.x_world
        if self.step_index == 0:
            x_cam = ref if ref is not None else _paper_x(feats)
            self.servo_cfg, self.pregrasp_standoff = first_goal(
                self.final_cfg,
                self.cfg,
                T,
                np.asarray(centre),
                feats.normal_cam,
                x_cam,
                plan.pattern,
                intr,
            )
        self.step_index += 1
        seen = (centre, feats.normal_cam, feats.warped_long, feats.warped_short, plan.pattern)
        cmd = servo_velocity(*seen, self.servo_cfg, self.kin.dt, reference_x=ref)
        if cmd.converged and self.servo_cfg is not self.final_cfg:
            self.servo_cfg = self.final_cfg  # at the first goal (lift, pre-grasp): on to d*
            cmd = servo_velocity(*seen, self.servo_cfg, self.kin.dt, reference_x=ref)
        g_px = np.asarray(feats.center_px, np.float64).copy()
        if cmd.converged:
            self.timings["control_law_s"].append(time.perf_counter() - t1)
            return ServoStep("converged", feats=feats, cmd=cmd, g_px=g_px)
        q, clamped = self.kin.step(obs.joints, np.asarray(cmd.velocity, np.float64))
        if self.fixed_world is None:
            # The next seed is this g′, moved into the next image by the camera's own motion
            # (forward kinematics): the paper seeds with the previous g′; at 30 Hz and up to
            # 0.5 m/s the image moves tens of pixels between frames.
            self.seed = project(self.kin.robot.camera_pose(q), self.g_world, intr, feats.center_px)
        self.timings["control_law_s"].append(time.perf_counter() - t1)
        return ServoStep("move", q=q, clamped=clamped, feats=feats, cmd=cmd, g_px=g_px)


def _paper_x(feats) -> np.ndarray:
    from pipeline.controller.check import paper_x_axis

    return paper_x_axis(feats)


class Mover:
    """The open-loop moves (module docstring) on the robot's own model."""

    def __init__(self, cfg, kin: Kinematics) -> None:
        self.cfg, self.kin = cfg, kin
        self._place_q: np.ndarray | None = None

    def approach(self, q: np.ndarray) -> list[np.ndarray]:
        """The joint commands, one per control period, of the approach along the camera axis
        from d* (at ``q``) until the lips touch the surface and press ``motion.press_depth``."""
        m, dt = self.cfg.motion, self.kin.dt
        travel = float(self.cfg.hand.standoff) - CUP_TIP_Z + float(m.press_depth)
        steps = max(1, int(math.ceil(travel / (float(m.approach_speed) * dt))))
        v = travel / (steps * dt)
        out = []
        for _ in range(steps):
            q, _ = self.kin.step(q, np.array([0.0, 0.0, v, 0.0, 0.0, 0.0]))
            out.append(q)
        return out

    def lift(self, q: np.ndarray) -> list[np.ndarray]:
        """The joint commands of the lift straight up (world z) by ``motion.lift_height`` at
        ``motion.lift_speed`` from ``q``."""
        m, dt = self.cfg.motion, self.kin.dt
        R_cam_world = self.kin.robot.camera_pose(q)[:3, :3].T
        twist = np.concatenate(
            [R_cam_world @ np.array([0.0, 0.0, float(m.lift_speed)]), np.zeros(3)]
        )
        steps = max(1, int(math.ceil(float(m.lift_height) / (float(m.lift_speed) * dt))))
        out = []
        for _ in range(steps):
            q, _ = self.kin.step(q, twist)
            out.append(q)
        return out

    def place_joints(self) -> np.ndarray:
        """Joints of the conveyor pose (camera at ``motion.place_position`` looking down)."""
        if self._place_q is None:
            robot = self.kin.robot
            T = robot.home_camera_pose().copy()
            T[:3, 3] = np.asarray(self.cfg.motion.place_position, np.float64)
            q_home = robot.home_q()
            res = robot.solve_ik(T, seed_q=q_home, obstacle_ids=[])
            robot.set_joints(q_home)
            if not res.ok:
                raise RuntimeError(
                    f"the conveyor pose {list(T[:3, 3])} is out of the robot's "
                    f"reach ({res.reason}): change motion.place_position"
                )
            self._place_q = res.q
        return self._place_q.copy()

    def move_time(self, q_from: np.ndarray, q_to: np.ndarray) -> float:
        """Seconds of a point-to-point move at ``motion.max_joint_speed`` and
        ``motion.max_joint_accel``."""
        m = self.cfg.motion
        return move_time(
            np.asarray(q_to) - np.asarray(q_from),
            float(m.max_joint_speed),
            float(m.max_joint_accel),
        )
