"""The run-time check, from what the camera sees: can the robot take this grasp, here, now?

The robot holds its own pybullet client (a kinematics and collision library, as a real cell's
software holds its own robot model): the ground and the bin of the static cell model
(``pipeline.cell.bin``), the robot (``pipeline.robot``), and a collision model of the heap. By
default that is :class:`pipeline.controller.heap_model.HeapModel`, built from the home depth
image alone, and tested by :class:`SeeingRobot`, the robot model that also keeps clear of it;
the "simulator knowledge" ablation row swaps in the heap's true boxes as bodies of the client
(``pipeline.world.knowledge``, through the :class:`CollisionModel` interface).

For a candidate (the surface the descriptor finds at it, its pattern): with
``evaluate.check_hand_fit`` the pattern's cups must fit on that surface (:func:`pattern_fits`);
then :func:`pipeline.labelling.grasp_check.check_grasp` (IK, joint limits, no contact at the
grasp pose and, with ``robot.path_check``, along the servo's predicted motion) against the bin
and the heap model without the grasped surface. With ``evaluate.preferred_bin_clearance`` the
check first asks for that much room from the bin on the servo's path and falls back to
``robot.path.bin_clearance``.

Frames: the home camera (OpenCV) for the surface; world (z up) for poses. Metres.
"""

from __future__ import annotations

import contextlib
import math
from types import SimpleNamespace
from typing import Protocol

import numpy as np
import pybullet as p

from pipeline.cell.bin import build_cell
from pipeline.controller.heap_model import (
    HeapCollider,
    HeapModel,
    HeapModelConfig,
    LinkSurface,
    plane_surface,
)
from pipeline.controller.observation import Observation
from pipeline.grasping.hand import cup_fits
from pipeline.labelling.grasp_check import GraspCheck, check_grasp
from pipeline.robot.model import Contact, Robot, robot_config

COLLISION_MODELS = ("observed", "truth")
HEAP = -2  # the heap model's obstacle id (no pybullet body has it)


class SeeingRobot(Robot):
    """The robot model whose collision checks also keep clear of the heap model: when
    ``in_collision``'s obstacles hold :data:`HEAP` and ``heap`` is set, every link is tested
    against it (``pipeline.controller.heap_model.HeapCollider``, the default margin), and a
    link within the margin is a contact with body :data:`HEAP`. The other obstacles go to
    :meth:`Robot.in_collision` as they are."""

    heap: HeapCollider | None = None
    surface: LinkSurface | None = None

    def in_collision(
        self, q, obstacle_body_ids, ignore_body_ids=(), margin=None, self_collision=True
    ) -> list[Contact]:
        ids = list(obstacle_body_ids)
        want_heap = HEAP in ids and self.heap is not None
        found = super().in_collision(
            q, [b for b in ids if b != HEAP], ignore_body_ids, margin, self_collision
        )
        if not want_heap:
            return found
        cid, rid = self.client, self.body_id
        links = [
            k
            for k in self.surface.points
            if self.heap.may_touch(*p.getAABB(rid, k, physicsClientId=cid))
        ]
        if links:
            states = p.getLinkStates(rid, links, physicsClientId=cid)
            for link, st in zip(links, states):
                R = np.asarray(p.getMatrixFromQuaternion(st[1])).reshape(3, 3)
                if self.heap.hits(self.surface.points[link] @ R.T + np.asarray(st[0])):
                    found.append(Contact(self.link_name[link], HEAP))
        return found


class CollisionModel(Protocol):
    """What the run-time check knows of the heap, as bodies in the check's client."""

    def update(self, obs: Observation) -> None:
        """A new home image (the start of a plan)."""

    def excluding(
        self, obs: Observation, uv: tuple[float, float], region: np.ndarray | None, plane=None
    ):
        """A context manager giving (obstacle body ids, body ids to ignore) for a grasp at
        pixel ``uv`` of ``obs`` on the surface ``region`` ((H, W) bool or None) whose plane is
        ``plane`` ((centre, normal), home camera frame, or None)."""

    def clear(self) -> None:
        """Remove every body the model added."""


class ObservedHeap:
    """The default :class:`CollisionModel`: :class:`HeapModel` from the home depth image,
    tested by the :class:`SeeingRobot` ``robot``."""

    def __init__(self, robot: SeeingRobot, bin_cfg, cfg: HeapModelConfig) -> None:
        self.robot, self.model = robot, HeapModel(bin_cfg, cfg)
        self.margin = float(robot.cfg.collision_margin)
        robot.surface = LinkSurface(robot, float(cfg.cell_m))

    def update(self, obs: Observation) -> None:
        self.model.update(obs)

    @contextlib.contextmanager
    def excluding(self, obs: Observation, uv, region, plane=None):
        m = self.model.map
        tol = self.model.cfg.surface_tolerance_m
        if tol > 0 and plane is not None and region is not None:
            region = plane_surface(obs, region, plane[0], plane[1], tol)
        self.robot.heap = HeapCollider(
            self.model.heights_without(region), m.origin, m.cell_m, self.margin
        )
        try:
            yield [HEAP], []
        finally:
            self.robot.heap = None

    def clear(self) -> None:
        self.model.map = None


def heap_model_config(cfg) -> HeapModelConfig:
    """The heap model's settings, ``cfg.evaluate.heap_model``."""
    h = cfg.evaluate.heap_model
    return HeapModelConfig(
        cell_m=float(h.cell_m),
        bin_tolerance_m=float(h.bin_tolerance_m),
        flying_tolerance_m=float(h.flying_tolerance_m),
        flying_min_neighbours=int(h.flying_min_neighbours),
        surface_tolerance_m=float(h.surface_tolerance_m),
    )


def hand_x_axis(feats, quarter_turn: bool) -> np.ndarray:
    """The surface axis whose warped view is nearer the image X (larger |cos|), or with
    ``quarter_turn`` the other one, signed towards +X of its warped view (camera frame)."""
    axes = [(feats.long_axis_cam, feats.warped_long), (feats.short_axis_cam, feats.warped_short)]
    nearer = int(np.argmax([abs(w[0]) for _, w in axes]))
    axis, warped = axes[1 - nearer if quarter_turn else nearer]
    return np.asarray(axis if warped[0] >= 0 else -axis, np.float64)


def paper_x_axis(feats) -> np.ndarray:
    """The hand's X by the paper's rule (camera frame): the surface axis whose warped view is
    nearer the image X, signed towards +X."""
    return hand_x_axis(feats, quarter_turn=False)


def pattern_fits(feats, pattern: str, hand_cfg, quarter_turn: bool = False) -> bool:
    """Whether ``pattern``'s active cups lie on the descriptor's surface ``feats``: the
    labelling stage's hand-level rule (``pipeline.grasping.hand.cup_fits``: each cup disc
    inside the surface rectangle, the area at least ``min_area_ratio`` × the active cups' area)
    without the labels' safety margin (a disc just inside the rectangle seals), with the hand's
    X by the paper's rule (``paper_x_axis``) and the cups on its Y, at ±``cup_offset`` for B and
    the one active cup on the centre for L and R. Turning the hand by 90°
    (``hand.rotations_deg``) leaves a single cup's fit unchanged, and B takes only 0 and 180°,
    so the paper's axis decides; with ``quarter_turn`` the hand's X is the other axis
    (:func:`hand_x_axis`), and B's cups lie along the paper's X."""
    x_is_long = (abs(feats.warped_long[0]) >= abs(feats.warped_short[0])) != quarter_turn
    half_x, half_y = (
        (feats.long_length / 2, feats.short_length / 2)
        if x_is_long
        else (feats.short_length / 2, feats.long_length / 2)
    )
    cups = 2 if pattern == "B" else 1
    cup_area = math.pi * (float(hand_cfg.cup_diameter) / 2) ** 2
    discs = SimpleNamespace(cup_diameter=float(hand_cfg.cup_diameter), margin=0.0)
    return (
        cup_fits(half_x, half_y, float(hand_cfg.cup_offset) if cups == 2 else 0.0, discs)
        and feats.area >= float(hand_cfg.min_area_ratio) * cups * cup_area
    )


class RunTimeCheck:
    """The robot's own client (bin, robot, heap model) and the check of one candidate.

    ``collision_model``: a factory ``(client) -> CollisionModel``; None: the observed heap
    (``evaluate.collision_model`` must then be ``observed``)."""

    def __init__(self, cfg, collision_model=None) -> None:
        self.cfg = cfg
        self.client = p.connect(p.DIRECT)
        self.bin_ids = build_cell(self.client, cfg.bin, cfg.physics)[1:]  # floor and walls
        self.robot = SeeingRobot(robot_config(cfg))
        self.robot.load(self.client, ground_z=-float(cfg.bin.floor_thickness))
        self.robot.set_joints(self.robot.home_q())
        self.heap = (
            collision_model(self.client)
            if collision_model is not None
            else ObservedHeap(self.robot, cfg.bin, heap_model_config(cfg))
        )
        pref = cfg.evaluate.preferred_bin_clearance
        # the bin clearance of the check's first pass, None: no first pass
        self.comfort = (
            None
            if pref is None or not bool(cfg.robot.path_check)
            else max(float(pref), float(cfg.robot.path.bin_clearance))
        )

    def update(self, obs: Observation) -> None:
        """Build the heap's collision model from a new home observation."""
        self.heap.update(obs)

    def check(
        self,
        obs: Observation,
        feats,
        centre_cam: np.ndarray,
        pattern: str,
        uv: tuple[float, float],
        hand_fit: bool,
        quarter_turn: bool = False,
    ) -> tuple[GraspCheck | None, str | None]:
        """(the passing check, None), or (None, the reason) for a grasp with ``pattern`` whose
        active cup goes on ``centre_cam`` (home camera, metres) on the descriptor's surface
        ``feats`` at pixel ``uv`` of the home observation ``obs``: "hand_fit" with
        ``hand_fit`` when the cups do not fit, else the failed check of ``check_grasp``. With
        ``quarter_turn`` the hand's X is turned by 90° from the paper's rule
        (:func:`hand_x_axis`); the passing check's ``x_world`` carries it to the
        servo."""
        cfg = self.cfg
        if hand_fit and not pattern_fits(feats, pattern, cfg.hand, quarter_turn):
            return None, "hand_fit"
        plane = (feats.center_cam, feats.normal_cam)
        with self.heap.excluding(obs, uv, feats.region, plane) as (obstacles, ignore):
            check = check_grasp(
                self.robot,
                cfg,
                cfg.hand,
                obs.T_world_cam,
                centre_cam,
                feats.normal_cam,
                feats.long_axis_cam,
                feats.short_axis_cam,
                hand_x_axis(feats, quarter_turn),
                pattern,
                obs.intrinsics,
                list(self.bin_ids) + list(obstacles),
                ignore,
                self.bin_ids,
                bin_clearances=([self.comfort] if self.comfort is not None else []) + [None],
            )
        if check.reason is None:
            return check, None
        return None, str(check.reason)

    def close(self) -> None:
        if p.isConnected(self.client):
            p.disconnect(self.client)
