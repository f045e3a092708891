"""The ray-cast renderer: hand-worked cases, and TinyRenderer as the reference on real heaps.

Where the two may differ, and how each difference is recognised (``classify``):
- *bin tie*: two bin parts meet in one plane (the floor's rim under a wall, the walls' outer
  faces) and both renderers see that plane at the same depth, but name different parts;
- *edge tie*: the pixel centre lies within 0.001 px of a silhouette edge, where float rounding
  decides (the ray cast through a centre moved by 0.001 px gives TinyRenderer's answer); also
  in depth, on one body: a face seen exactly edge-on at a silhouette corner, where the ray
  cast's depths through the centres moved by 0.001 px bracket TinyRenderer's;
- *crack*: TinyRenderer misses a pixel on the diagonal shared by a face's two triangles (it
  sees farther, and its four neighbours all show the ray cast's surface);
- *near plane*: TinyRenderer drops every triangle that has a vertex nearer than the near plane,
  so a box that crosses it loses whole faces; the ray cast clips it pixel by pixel.
Anything else is a failure.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as p
import pytest
from omegaconf import OmegaConf

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.camera.raycast import (
    UnsupportedGeometry,
    boxes_from_pybullet,
    fill_ground,
    raycast_boxes,
)
from pipeline.camera.render import render_depth
from pipeline.cell.bin import build_cell
from pipeline.runtime.cli import compose
from pipeline.simulation.heap import drop_heap
from pipeline.simulation.views import closeup_poses

SR300 = Intrinsics(416, 416, 411.7, 411.7, 207.5, 207.5)
EDGE_TIE_PX = 1e-3
DEPTH_TOL_M = 1e-4  # the 0.1 mm


# ------------------------------------------------------------------------ hand-worked cases
def test_near_plane_clips_pixel_by_pixel(client, static_box):
    """Camera 0.3 m above a floor slab (top at z = 0) and a 0.1 m cube spanning z ∈ [0.15, 0.25]:
    the cube's top is 0.05 m from the camera, nearer than the 0.1 m near plane, so the central
    ray enters the cube before the near plane and sees its bottom face from inside, at depth
    0.3 − 0.15 = 0.15 m. Rays past the cube see the floor at 0.3 m."""
    floor = static_box(client, [0.5, 0.5, 0.01], [0, 0, -0.01])
    cube = static_box(client, [0.05, 0.05, 0.05], [0, 0, 0.2])
    frame = render_depth(client, SR300, camera_pose_above_bin(0.3), 0.1, 2.0, renderer="raycast")
    assert frame.body_ids[208, 208] == cube
    assert frame.depth_m[208, 208] == pytest.approx(0.15, abs=1e-6)
    # Along row v = 208 (y ≈ 0) a ray x = xn·z is inside the cube at the near plane while
    # xn·0.1 < 0.05, i.e. up to u = 207.5 + 0.5·411.7 = 413.35; it then leaves through the side
    # face x = 0.05 at z = 0.05/xn. Pixel 413 (xn = 205.5/411.7) sees that face from inside at
    # z = 0.10017 m; pixel 414 is outside the cube at the near plane and sees the floor.
    assert frame.body_ids[208, 413] == cube
    assert frame.depth_m[208, 413] == pytest.approx(0.05 * 411.7 / 205.5, abs=1e-6)
    assert frame.body_ids[208, 414] == floor
    assert frame.depth_m[208, 414] == pytest.approx(0.3, abs=1e-6)


def test_far_limit_and_nothing_seen(client, static_box):
    """A floor 2.5 m away lies beyond far = 2 m: no body, depth = far; the analytic ground
    (z = −2.5) is not filled beyond far either, but a ground at z = −1.5 is."""
    static_box(client, [5, 5, 0.01], [0, 0, -2.51])
    T = camera_pose_above_bin(0.0)
    frame = render_depth(client, SR300, T, 0.1, 2.0, renderer="raycast", ground=(-2.5, 7))
    assert (frame.body_ids == -1).all() and (frame.depth_m == 2.0).all()
    frame = render_depth(client, SR300, T, 0.1, 2.0, renderer="raycast", ground=(-1.5, 7))
    assert (frame.body_ids == 7).all()
    assert frame.depth_m[208, 208] == pytest.approx(1.5, abs=1e-6)


def test_tilted_box_depth_by_hand(client, static_box):
    """A box turned 30° about world x, its top face centre 0.5 m below the camera: along the
    optical axis the top face is met at z = 0.5 m exactly. One pixel row down the ray is
    z·(0, yn, 1), yn = 1/411.7, i.e. the world point (0, −yn·z, 0.6 − z); on the plane
    n·(X − c) = 0 with n = (0, −sin 30°, cos 30°), c = (0, 0, 0.1):
    sin 30°·yn·z + cos 30°·(0.5 − z) = 0, so z = 0.5 / (1 − yn·tan 30°)."""
    angle = np.radians(30)
    q = p.getQuaternionFromEuler([angle, 0, 0])
    half = np.array([0.1, 0.1, 0.02])
    normal = np.array([0, -np.sin(angle), np.cos(angle)])  # the box's z axis in the world
    top_centre = np.array([0.0, 0.0, 0.1])
    box = static_box(client, half.tolist(), (top_centre - half[2] * normal).tolist(), q)
    T = camera_pose_above_bin(0.6)
    intr = Intrinsics(416, 416, 411.7, 411.7, 208.0, 208.0)  # pixel (208, 208) on the axis
    frame = render_depth(client, intr, T, 0.1, 2.0, renderer="raycast")
    assert frame.body_ids[208, 208] == box
    assert frame.depth_m[208, 208] == pytest.approx(0.5, abs=1e-6)
    yn = 1 / 411.7
    z = 0.5 / (1 - yn * np.tan(angle))
    assert frame.depth_m[209, 208] == pytest.approx(z, abs=1e-6)


def test_only_boxes_are_drawn(client, static_box):
    """A visible sphere cannot be ray-cast: a clear error naming the fix; leaving it out of
    ``bodies`` draws the rest."""
    box = static_box(client, [0.05, 0.05, 0.05], [0, 0, 0.05])
    col = p.createCollisionShape(p.GEOM_SPHERE, radius=0.05, physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_SPHERE, radius=0.05, physicsClientId=client)
    ball = p.createMultiBody(0, col, vis, basePosition=[0.2, 0, 0.05], physicsClientId=client)
    T = camera_pose_above_bin(0.6)
    with pytest.raises(UnsupportedGeometry, match="camera.renderer=tinyrenderer"):
        render_depth(client, SR300, T, 0.1, 2.0, renderer="raycast")
    frame = render_depth(client, SR300, T, 0.1, 2.0, renderer="raycast", bodies=[box])
    assert set(np.unique(frame.body_ids)) == {-1, box}
    assert ball not in frame.body_ids


def test_transparent_shapes_are_skipped_and_unknown_renderer_refused(client, static_box):
    body = static_box(client, [0.5, 0.5, 0.01], [0, 0, 0])
    p.changeVisualShape(body, -1, rgbaColor=[1, 1, 1, 0], physicsClientId=client)
    assert boxes_from_pybullet(client) == []
    with pytest.raises(ValueError, match="camera.renderer must be one of"):
        render_depth(client, SR300, camera_pose_above_bin(0.6), 0.1, 2.0, renderer="embree")


def test_box_reaching_behind_the_camera(client, static_box):
    """A wall x ∈ [0.05, 1.05], y ∈ [−1, 1], z ∈ [−1, 0.5] beside a camera at (0, 0, 0.12)
    looking down: some corners are behind the camera (their projection is unbounded), so every
    pixel is tested. Pixel u = 407 (xn = 199.5/411.7) meets the wall's face x = 0.05 at
    z = 0.05/xn = 0.10318 m, beyond the near plane; pixel u = 207 (xn < 0) never meets it."""
    wall = static_box(client, [0.5, 1.0, 0.75], [0.55, 0, -0.25])
    frame = render_depth(client, SR300, camera_pose_above_bin(0.12), 0.1, 2.0, renderer="raycast")
    assert frame.body_ids[208, 407] == wall
    assert frame.depth_m[208, 407] == pytest.approx(0.05 * 411.7 / 199.5, abs=1e-6)
    assert frame.body_ids[208, 207] == -1


def test_fill_ground_by_hand():
    """Camera 0.625 m above the bin floor, ground 0.02 m below it: every empty pixel gets
    z = 0.645 m (a horizontal plane seen by a camera looking straight down has one z-depth)."""
    depth = np.full((416, 416), 2.0, np.float32)
    ids = np.full((416, 416), -1, np.int32)
    ids[:100] = 3
    fill_ground(depth, ids, SR300, camera_pose_above_bin(0.625), -0.02, 9, 2.0)
    assert (ids[:100] == 3).all() and (depth[:100] == 2.0).all()
    assert (ids[100:] == 9).all() and np.allclose(depth[100:], 0.645, atol=1e-6)


# ------------------------------------------------------------------- against TinyRenderer
def _crosses_near(box, T_world_cam: np.ndarray, near: float) -> bool:
    T = np.linalg.inv(T_world_cam) @ box.T_world_box
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    z = (corners * box.half_extents) @ T[:3, :3].T[2] + T[2, 3]
    return bool(z.min() < near)


def classify(tiny, ray, boxes, bin_ids, T, intr, near, far, ground_id) -> dict[str, int]:
    """Count the pixels where the two frames differ, by the kinds of the module docstring;
    ``unexplained`` lists the pixels no kind accounts for. ``depth_max_m``: the largest depth
    difference over the pixels where both name the same body (near-plane boxes and depth edge
    ties excepted)."""
    by_id = {b.body_id: b for b in boxes}
    near_ids = {i for i, b in by_id.items() if _crosses_near(b, T, near)}
    out = {
        "pixels": tiny.body_ids.size,
        "bin_tie": 0,
        "edge_tie": 0,
        "depth_edge_tie": 0,
        "crack": 0,
        "near_plane": 0,
        "unexplained": [],
    }
    H, W = tiny.body_ids.shape
    for v, u in zip(*np.nonzero(tiny.body_ids != ray.body_ids)):
        a, b = int(tiny.body_ids[v, u]), int(ray.body_ids[v, u])
        da, db = float(tiny.depth_m[v, u]), float(ray.depth_m[v, u])
        if a in near_ids or b in near_ids:
            out["near_plane"] += 1
            continue
        if a in bin_ids and b in bin_ids and abs(da - db) < DEPTH_TOL_M:
            out["bin_tie"] += 1
            continue
        nb = [
            tiny.body_ids[y, x]
            for y, x in ((v - 1, u), (v + 1, u), (v, u - 1), (v, u + 1))
            if 0 <= y < H and 0 <= x < W
        ]
        if da > db and len(nb) == 4 and all(n == b for n in nb):
            out["crack"] += 1
            continue
        tie = False
        for du, dv in ((EDGE_TIE_PX, 0), (-EDGE_TIE_PX, 0), (0, EDGE_TIE_PX), (0, -EDGE_TIE_PX)):
            moved = dataclasses.replace(intr, cx=intr.cx - du, cy=intr.cy - dv)
            _, ids = raycast_boxes(boxes, moved, T, near, far)
            seen = int(ids[v, u])
            if seen == a or (seen == -1 and a == ground_id):  # −1 → the ground fills it
                tie = True
                break
        if tie:
            out["edge_tie"] += 1
        else:
            out["unexplained"].append((int(v), int(u), a, b, da, db))
    same = tiny.body_ids == ray.body_ids
    for i in near_ids:
        same &= ray.body_ids != i
    diff = np.abs(tiny.depth_m.astype(np.float64) - ray.depth_m)
    # Depth edge ties: a face seen exactly edge-on at a silhouette corner, where moving the
    # pixel centre by 0.001 px moves the ray cast's depth across TinyRenderer's.
    shifted = None
    for v, u in zip(*np.nonzero(same & (diff >= DEPTH_TOL_M))):
        if shifted is None:
            shifted = [
                raycast_boxes(
                    boxes, dataclasses.replace(intr, cx=intr.cx - du, cy=intr.cy - dv), T, near, far
                )
                for du, dv in (
                    (EDGE_TIE_PX, 0),
                    (-EDGE_TIE_PX, 0),
                    (0, EDGE_TIE_PX),
                    (0, -EDGE_TIE_PX),
                )
            ]
        seen = [float(ray.depth_m[v, u])] + [
            float(d[v, u]) for d, ids in shifted if int(ids[v, u]) == int(ray.body_ids[v, u])
        ]
        if min(seen) - DEPTH_TOL_M <= float(tiny.depth_m[v, u]) <= max(seen) + DEPTH_TOL_M:
            out["edge_tie"] += 1
            out["depth_edge_tie"] += 1
            same[v, u] = False
    out["depth_max_m"] = float(diff[same].max())
    return out


def _compare(client, cfg, cell, poses, totals, bodies=None):
    intr = Intrinsics.from_config(cfg.camera)
    near, far = cfg.camera.near, cfg.camera.far
    ground = (-cfg.bin.floor_thickness, cell[0])
    boxes = boxes_from_pybullet(client, bodies)
    for T in poses:
        tiny = render_depth(client, intr, T, near, far, ground=ground, renderer="tinyrenderer")
        ray = render_depth(
            client, intr, T, near, far, ground=ground, renderer="raycast", bodies=bodies
        )
        c = classify(tiny, ray, boxes, set(cell[1:]), T, intr, near, far, cell[0])
        for k in ("pixels", "bin_tie", "edge_tie", "depth_edge_tie", "crack", "near_plane"):
            totals[k] += c[k]
        totals["frames"] += 1
        totals["unexplained"] += c["unexplained"]
        totals["depth_max_m"] = max(totals["depth_max_m"], c["depth_max_m"])


@pytest.mark.slow
def test_heaps_match_tinyrenderer():
    """12 heaps (6 of 20 boxes, 6 of 0–20), each seen from the generation camera and from
    three close-up poses on box faces (0.15 m, the servo's d*, 0.2 m and 0.3 m, tilted with the
    faces): identical masks but for the counted ties, depth within 0.1 mm."""
    cfg = OmegaConf.to_object(compose("generate", ["experiment=smoke"]))
    client = p.connect(p.DIRECT)
    totals = {
        "frames": 0,
        "pixels": 0,
        "bin_tie": 0,
        "edge_tie": 0,
        "depth_edge_tie": 0,
        "crack": 0,
        "near_plane": 0,
        "unexplained": [],
        "depth_max_m": 0.0,
    }
    try:
        for i in range(12):
            boxes = dataclasses.replace(cfg.boxes, min_count=20) if i < 6 else cfg.boxes
            cell = build_cell(client, cfg.bin, cfg.physics)
            heap = drop_heap(
                client, np.random.default_rng([2024, 0, i]), boxes, cfg.bin, cfg.physics
            )
            if not heap.boxes:
                continue
            poses = [camera_pose_above_bin(cfg.camera.height_above_bin_floor)] + closeup_poses(
                heap.boxes, np.random.default_rng([2024, 1, i]), (0.15, 0.2, 0.3)
            )
            _compare(client, cfg, cell, poses, totals)
    finally:
        p.disconnect(client)
    print(totals)
    assert totals["frames"] >= 40
    assert totals["unexplained"] == []
    assert totals["depth_max_m"] < DEPTH_TOL_M
    # ties at edges are rare: at most one pixel in 10,000 (bin ties are whole coplanar faces)
    assert totals["edge_tie"] + totals["crack"] <= totals["pixels"] * 1e-4


@pytest.mark.slow
def test_closed_loop_frames_match_tinyrenderer():
    """Every frame the hand camera takes during a closed-loop trial (3 boxes, the training-free
    planarity planner), rendered both ways: the same classification as above."""
    from pipeline.controller.planning import DexNetStylePlanner
    from pipeline.world.trial import make_runner

    cfg = compose(
        "evaluate",
        ["experiment=default", "evaluate.boxes_per_trial=3", "evaluate.dexnet_variant=planarity"],
    )
    runner = make_runner(
        cfg,
        "dexnet",
        lambda cell: DexNetStylePlanner(cfg, "planarity", cell.robot.home_camera_pose(), None),
    )
    cell = runner.cell
    totals = {
        "frames": 0,
        "pixels": 0,
        "bin_tie": 0,
        "edge_tie": 0,
        "depth_edge_tie": 0,
        "crack": 0,
        "near_plane": 0,
        "unexplained": [],
        "depth_max_m": 0.0,
    }
    render = cell.render

    def render_both(T_world_cam=None):
        frame = render(T_world_cam)
        # the closed loop's camera sees the bin and the boxes: the robot and its pedestal
        # (beside the bin, in view when the camera turns towards it) are moved out of sight
        hidden = [cell.robot.body_id, cell.robot.pedestal_id]
        poses = [p.getBasePositionAndOrientation(b, physicsClientId=cell.client) for b in hidden]
        for b, (_, orn) in zip(hidden, poses):
            p.resetBasePositionAndOrientation(b, [0, 0, -50], orn, physicsClientId=cell.client)
        try:
            _compare(
                cell.client, cfg, cell.cell_ids, [frame.T_world_cam], totals, bodies=cell.obstacles
            )
        finally:
            for b, (pos, orn) in zip(hidden, poses):
                p.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=cell.client)
        return frame

    cell.render = render_both
    try:
        runner.run_trial(
            0, np.random.default_rng([2024, 31, 0]), np.random.default_rng([2024, 37, 0])
        )
    finally:
        cell.close()
        runner.robot_side.close()
    print(totals)
    assert totals["frames"] >= 20
    assert totals["unexplained"] == []
    assert totals["depth_max_m"] < DEPTH_TOL_M
    assert totals["edge_tie"] + totals["crack"] <= totals["pixels"] * 1e-4


def test_box_shapes_read_from_pybullet(client, static_box):
    """``boxes_from_pybullet`` reads half extents and the pose: a 0.12 × 0.075 × 0.023 m box at
    (0.1, −0.05, 0.2) turned 90° about z."""
    q = p.getQuaternionFromEuler([0, 0, np.pi / 2])
    body = static_box(client, [0.06, 0.0375, 0.0115], [0.1, -0.05, 0.2], q)
    (shape,) = boxes_from_pybullet(client)
    assert shape.body_id == body
    assert shape.half_extents == pytest.approx([0.06, 0.0375, 0.0115])
    assert shape.T_world_box[:3, 3] == pytest.approx([0.1, -0.05, 0.2])
    assert shape.T_world_box[:3, 0] == pytest.approx([0, 1, 0], abs=1e-9)


def test_shape_cache_reads_poses_afresh(client, static_box):
    """With a cache, a body's shapes are read once and its pose every time: after the box
    moves, the cached read gives the same shapes, bit for bit, as a read without the cache."""
    body = static_box(client, [0.06, 0.0375, 0.0115], [0.1, -0.05, 0.2])
    cache: dict = {}
    boxes_from_pybullet(client, [body], cache)
    assert set(cache) == {body}
    q = p.getQuaternionFromEuler([0.3, 0.1, 1.2])
    p.resetBasePositionAndOrientation(body, [0.02, 0.03, 0.25], q, physicsClientId=client)
    (cached,) = boxes_from_pybullet(client, [body], cache)
    (fresh,) = boxes_from_pybullet(client, [body])
    assert cached.T_world_box.tobytes() == fresh.T_world_box.tobytes()
    assert cached.half_extents.tobytes() == fresh.half_extents.tobytes()
    assert cached.T_world_box[:3, 3] == pytest.approx([0.02, 0.03, 0.25])


def test_generation_uses_the_configured_renderer():
    """``camera.renderer`` reaches the generation's scenes: the ray-cast scene and the
    TinyRenderer scene of one seed hold the same heap, the same mask but for ties, and depth
    within 0.1 mm."""
    from pipeline.simulation.scene import connect, scene_rng, simulate_scene

    client = connect()
    try:
        scenes = {}
        for name in ("raycast", "tinyrenderer"):
            cfg = OmegaConf.to_object(
                compose("generate", ["experiment=smoke", f"camera.renderer={name}"])
            )
            scenes[name] = simulate_scene(client, cfg, scene_rng(3, 0, 4))
    finally:
        p.disconnect(client)
    a, b = scenes["raycast"], scenes["tinyrenderer"]
    assert [x.position.tolist() for x in a.boxes] == [x.position.tolist() for x in b.boxes]
    assert np.mean(a.mask != b.mask) < 1e-4
    same = a.mask == b.mask
    assert np.abs(a.depth_m - b.depth_m)[same].max() < DEPTH_TOL_M


def test_a_mistyped_renderer_is_refused_before_any_work(tmp_path):
    from pipeline.stages.generate import generate

    cfg = compose(
        "generate", ["experiment=smoke", f"paths.root={tmp_path}", "camera.renderer=raytrace"]
    )
    with pytest.raises(ValueError, match="camera.renderer must be one of tinyrenderer, raycast"):
        generate(cfg)
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").rglob("*.npz"))
