"""The oracle planner: the labelling stage's own grasp points and classes on the home image.

A stand-in for a network that predicts its training labels perfectly. At home the camera's
frame is labelled exactly as the labelling stage labels a generated scene
(``pipeline.labelling.scene.label_scene``: surfaces by RANSAC on the ideal depth and the simulator's
instance mask, the hand-level class, the robot-level check against the heap's true box poses),
and the graspable points are ranked by Eq. 7 like the DCNN's candidates
(``pipeline.planner.ranking``). Its Table 3 row is the ceiling of the cell's execution: it
separates what perception loses from what execution loses. It knows the simulator's ground
truth, so it never stands in for the DCNN's figures.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.geometry import Intrinsics, pose_matrix
from pipeline.controller.observation import Observation
from pipeline.controller.planning import Grasp
from pipeline.dataset.scenes import Box, Scene
from pipeline.grasping.types import GraspClass
from pipeline.planner.decode import GraspPrediction
from pipeline.planner.ranking import rank_grasps
from pipeline.world.cell import Frame, PickCell


class OraclePlanner:
    """``plan(observation, rng)`` → ranked grasps (``pipeline.controller.planning``), from the
    truth behind the observation: the cell's ``last_frame`` (ideal depth, body ids, pose) and
    its true box poses. The one planner that plans from ground truth; its grasps go through the
    robot's own selection and check like any planner's."""

    def __init__(self, cfg, cell: PickCell) -> None:
        from pipeline.labelling.robot_check import RobotChecker
        from pipeline.planner.planner import ranking_config

        self.cfg, self.cell = cfg, cell
        self.robot = RobotChecker(cfg)
        self.ranking = ranking_config(cfg, threshold=0.5)

    def scene(self, frame: Frame, intr: Intrinsics) -> Scene:
        """The home frame as a labelled scene: ideal depth, instance mask, true box poses."""
        mask = np.zeros(frame.body_ids.shape, np.uint8)
        T_cam_world = np.linalg.inv(frame.T_world_cam)
        boxes = []
        for k, (body, info) in enumerate(self.cell.boxes.items(), start=1):
            mask[frame.body_ids == body] = k
            T = pose_matrix(*self.cell.box_pose(body))
            boxes.append(
                Box(
                    instance=k,
                    type_index=-1,
                    type_name=info["type"],
                    size=np.asarray(info["size"], np.float64),
                    T_world_box=T,
                    T_cam_box=T_cam_world @ T,
                )
            )
        return Scene(
            depth_m=frame.depth_clean_m,
            depth_clean_m=frame.depth_clean_m,
            mask=mask,
            boxes=boxes,
            intrinsics=intr,
            T_world_cam=frame.T_world_cam,
            split="",
            index=0,
            seed=(0, 0, 0),
            settle_steps=0,
            settled=True,
        )

    def plan(self, observation: Observation, rng=None) -> list[Grasp]:
        """The labels of the home frame behind ``observation`` as grasps, ranked by Eq. 7."""
        from pipeline.labelling.scene import label_scene

        frame = self.cell.last_frame
        if frame is None or not np.array_equal(frame.T_world_cam, observation.T_world_cam):
            raise ValueError(
                "the oracle planner plans on the cell's latest observation "
                "(PickCell.observe), and this observation is not it"
            )
        intrinsics = observation.intrinsics
        scene = self.scene(frame, intrinsics)
        rows, _, _, _ = label_scene(
            scene, self.cfg, self.robot, self.cfg.bin, density=float(self.cfg.eval_boxes.density)
        )
        preds = []
        for uv, cls in zip(rows["uv"], rows["grasp_class"]):
            if int(cls) == int(GraspClass.NG):
                continue
            probs = np.zeros(len(GraspClass), np.float32)
            probs[int(cls)] = 1.0
            preds.append(
                GraspPrediction(
                    u=float(uv[0]),
                    v=float(uv[1]),
                    grasp_class=GraspClass(int(cls)),
                    probability=1.0,
                    class_probs=probs,
                )
            )
        ranked = rank_grasps(preds, frame.depth_clean_m, intrinsics, self.ranking)
        return [
            Grasp(u=float(c.u), v=float(c.v), pattern=c.grasp_class.name, score=float(c.score))
            for c in ranked
        ]
