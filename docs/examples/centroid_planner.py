"""A complete plug-in planner: grasp each smooth patch of the heap at its centroid.

Run it in the closed loop, beside the built-in planners, from the repository's root:

    make evaluate ARGS="evaluate.planners=[dcnn,docs.examples.centroid_planner:CentroidPlanner]"

The heap is split into patches where the depth jumps (an edge between boxes) and the bin floor
is left out; each patch large enough for a cup is grasped at the pixel nearest its centroid,
with both cups where the patch is wide enough for them, and the highest patches come first.
No learning: a baseline a learned planner should beat. See docs/planners.md.
"""

from __future__ import annotations

import cv2
import numpy as np

from pipeline.controller.planning import Grasp


class CentroidPlanner:
    def __init__(self, cfg):
        self.max_step_m = 0.004  # a larger depth step between neighbours is an edge
        self.floor_m = 0.01  # points this low (world z) are the bin floor
        self.two_cups_m = 2 * (float(cfg.hand.cup_offset) + float(cfg.hand.cup_diameter) / 2)
        self.one_cup_m = float(cfg.hand.cup_diameter)

    def plan(self, observation, rng):
        depth = np.asarray(observation.depth_m, np.float32)
        intr, T = observation.intrinsics, observation.T_world_cam
        h, w = depth.shape
        u, v = np.meshgrid(np.arange(w), np.arange(h))
        # each pixel's height above the bin floor (world z), from the camera's pose
        rays = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(depth)])
        height = np.einsum("k,khw->hw", T[2, :3], rays * depth) + T[2, 3]
        step = np.maximum(
            np.abs(np.diff(depth, axis=0, append=0)), np.abs(np.diff(depth, axis=1, append=0))
        )
        smooth = (depth > 0) & (step < self.max_step_m) & (height > self.floor_m)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(smooth.astype(np.uint8), 4)
        grasps = []
        for k in range(1, count):
            if stats[k, cv2.CC_STAT_AREA] < 50:
                continue
            vs, us = np.nonzero(labels == k)
            pts = np.stack([us, vs], axis=1).astype(np.float32)
            (_, _), (a, b), _ = cv2.minAreaRect(pts)
            metres_per_px = float(np.median(depth[vs, us])) / intr.fx
            short = min(a, b) * metres_per_px
            pattern = "B" if short >= self.two_cups_m else "L" if short >= self.one_cup_m else None
            if pattern is None:
                continue
            i = np.argmin((us - us.mean()) ** 2 + (vs - vs.mean()) ** 2)  # nearest the centroid
            z = float(height[vs[i], us[i]])
            grasps.append(Grasp(u=float(us[i]), v=float(vs[i]), pattern=pattern, score=z))
        return sorted(grasps, key=lambda g: -g.score)
