"""The out-of-domain training data of the Dex-Net-style baseline: the convex ray-cast renderer
(pipeline.camera.raycast_convex) against hand-worked depths, the box renderer and TinyRenderer;
labels of candidates on object bodies (pipeline.dexnet.ood.label_candidates, by contact_mesh);
one object heap scene built, rendered, sampled and labelled at a small image size; and the
config checks of the gqcnn_ood variant.

Looking-down camera: ``camera_pose_above_bin(0.55)``, 0.55 m above world z = 0 (camera z =
world -z), so a surface at world height h has z-depth 0.55 - h.
"""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest
from conftest import conf_section, default_config

from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
from pipeline.camera.raycast import boxes_from_pybullet, raycast_boxes
from pipeline.camera.raycast_convex import (
    box_shape,
    convex_from_pybullet,
    convex_shape,
    raycast_convex,
)
from pipeline.camera.render import render_depth
from pipeline.dexnet.contact import REASONS
from pipeline.dexnet.sampling import Candidates
from pipeline.grasping.suction import SuctionModelConfig
from pipeline.simulation.objects import create_body, cylinder, prism, regular_polygon

T_DOWN = camera_pose_above_bin(0.55)
INTR = Intrinsics(160, 160, 400.0, 400.0, 79.5, 79.5)  # 1.2 mm a pixel at 0.47 m


def _pixel(x: float, y: float, z: float) -> tuple[int, int]:
    """The pixel (u, v) that sees world point (x, y, z) (camera x = world x, y = -world y)."""
    d = 0.55 - z
    return int(round(INTR.fx * x / d + INTR.cx)), int(round(INTR.fy * -y / d + INTR.cy))


def _upright_cylinder(client, radius=0.03, length=0.08, x=0.0):
    """A cylinder standing on z = 0, axis vertical, at (x, 0): top face at z = length."""
    return create_body(
        client, cylinder(radius, length, 64), 400.0, 0.5, [x, 0.0, length / 2], [0, 0, 0, 1]
    )


def test_convex_ray_cast_by_hand(client):
    """Top face of an upright cylinder (h = 0.08 m): depth 0.47 m at its centre; a square prism
    (apothem 25 mm, 30 mm tall) beside it: 0.52 m; between them nothing (far)."""
    cyl = _upright_cylinder(client)
    square = prism(regular_polygon(4, 0.025 * np.sqrt(2)), 0.03)  # a 50 mm x 50 mm square
    box = create_body(
        client, square, 400.0, 0.5, [0.1, 0.0, 0.015], p.getQuaternionFromEuler([0, 0, np.pi / 4])
    )
    depth, ids = raycast_convex(convex_from_pybullet(client), INTR, T_DOWN, 0.1, 2.0)
    u, v = _pixel(0.0, 0.0, 0.08)
    assert ids[v, u] == cyl and depth[v, u] == pytest.approx(0.47, abs=1e-6)
    u, v = _pixel(0.1, 0.0, 0.03)
    assert ids[v, u] == box and depth[v, u] == pytest.approx(0.52, abs=1e-6)
    u, v = _pixel(0.055, 0.0, 0.0)  # 25 mm from the cylinder's rim, 20 mm from the prism's face
    assert ids[v, u] == -1 and depth[v, u] == pytest.approx(2.0)
    # the 64-gon's cap is one plane after merging its 62 triangles: 64 sides + 2 caps
    shapes = {s.body_id: s for s in convex_from_pybullet(client)}
    assert len(shapes[cyl].offsets) == 66 and len(shapes[box].offsets) == 6


def test_convex_ray_cast_equals_the_box_ray_cast(client, static_box):
    """Boxes drawn as convex solids give the slab test's image (within float32 rounding)."""
    static_box(client, [0.05, 0.03, 0.02], [0.0, 0.0, 0.02])
    static_box(
        client, [0.04, 0.04, 0.01], [0.08, 0.05, 0.05], p.getQuaternionFromEuler([0.3, -0.2, 0.7])
    )
    d_box, id_box = raycast_boxes(boxes_from_pybullet(client), INTR, T_DOWN, 0.1, 2.0)
    d_cvx, id_cvx = raycast_convex(convex_from_pybullet(client), INTR, T_DOWN, 0.1, 2.0)
    same = id_box == id_cvx
    assert same.mean() > 0.999  # pixel centres on an edge may go either way
    assert np.abs(d_box[same] - d_cvx[same]).max() < 1e-5
    # and a box given by its pose directly has the hull's planes
    hull = convex_shape(7, box_shape(7, np.eye(4), np.array([0.1, 0.2, 0.3])).vertices)
    assert sorted(np.round(hull.offsets, 9)) == [0.1, 0.1, 0.2, 0.2, 0.3, 0.3]


def test_convex_ray_cast_matches_tinyrenderer_on_meshes(client):
    """The rasteriser draws create_body's visual mesh, the same solid: the same body wherever
    both see one but at silhouette pixels, and the same depth within 0.1 mm inside."""
    _upright_cylinder(client, 0.03, 0.08, -0.05)
    create_body(
        client,
        prism(regular_polygon(5, 0.04), 0.05),
        400.0,
        0.5,
        [0.06, 0.02, 0.03],
        p.getQuaternionFromEuler([0.4, 0.2, 0.1]),
    )
    d_cvx, id_cvx = raycast_convex(convex_from_pybullet(client), INTR, T_DOWN, 0.1, 2.0)
    frame = render_depth(client, INTR, T_DOWN, 0.1, 2.0, renderer="tinyrenderer")
    seen = id_cvx >= 0
    assert np.mean(frame.body_ids[seen] == id_cvx[seen]) > 0.98
    interior = seen & (frame.body_ids == id_cvx)
    assert np.median(np.abs(frame.depth_m[interior] - d_cvx[interior])) < 1e-4


def test_labels_come_from_the_mesh_contact_model(client):
    """A lone upright cylinder (r = 30 mm, h = 80 mm, 400 kg/m^3: 0.090 kg): a cup straight down
    on the centre of its top face seals and holds (weight 0.89 N along the axis, no moment):
    ``ok``. Its robust quality is the share of perturbed grasps whose axis is tilted by at most
    atan(c / 2 r) = atan(3 / 18) = 9.46 deg: a cup of radius r = 9 mm tilted by theta on a flat
    face spreads its rim's heights by 2 r tan(theta), over the 3 mm compliance beyond that (the
    2 mm shifts keep the rim on the 30-mm face, and a tilt this small leaves the wrench well
    inside its limits). A cup 60 mm to the side, over the floor, does not start on the
    cylinder: ``not_on_box``, quality 0."""
    from pipeline.dexnet.contact import perturbed_grasps
    from pipeline.dexnet.ood import label_candidates

    floor_col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1, 1, 0.01], physicsClientId=client)
    floor = p.createMultiBody(0, floor_col, -1, basePosition=[0, 0, -0.01], physicsClientId=client)
    body = _upright_cylinder(client)
    depth, ids = raycast_convex(convex_from_pybullet(client), INTR, T_DOWN, 0.1, 2.0)
    mask = (ids == body).astype(np.uint8)
    on, off = _pixel(0.0, 0.0, 0.08), _pixel(0.06, 0.0, 0.0)
    axis = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])  # straight down = camera +z
    point = np.array([[0.0, 0.0, 0.47], [0.06, 0.0, 0.55]])  # camera frame
    cands = Candidates(
        uv=np.array([on, off]), point=point, axis=axis, depth=point[:, 2], angle=np.zeros(2)
    )
    quality, reason = label_candidates(
        client,
        [body],
        cands,
        depth,
        mask,
        INTR,
        T_DOWN,
        default_config(SuctionModelConfig),
        np.random.default_rng(0),
    )
    assert [REASONS[r] for r in reason] == ["ok", "not_on_box"]
    cfg = default_config(SuctionModelConfig)
    _, axes = perturbed_grasps(point, axis, cfg, np.random.default_rng(0))  # as labelled
    tilt = np.degrees(np.arccos(np.clip(axes[0] @ axis[0], -1.0, 1.0)))  # (K,)
    limit = np.degrees(np.arctan(cfg.compliance / (2 * cfg.cup_radius)))
    assert limit == pytest.approx(9.46, abs=0.01)
    assert 0.5 <= np.mean(tilt <= limit) < 1.0  # a positive, though not every grasp holds
    assert quality.tolist() == [np.mean(tilt <= limit), 0.0]
    assert floor not in (body,)


def _small_cfg(*extra: str):
    """A composed config with a 160-px camera (same field of view: fx scaled by 160/416) and a
    border and crop window scaled to match, so that candidates exist on a small image."""
    from pipeline.runtime.cli import compose

    return compose(
        "baseline",
        [
            "experiment=smoke",
            "camera.width=160",
            "camera.height=160",
            "camera.fx=158.35",
            "camera.fy=158.35",
            "camera.cx=79.5",
            "camera.cy=79.5",
            "dexnet.border_px=26",
            "dexnet.crop.window_px=24",
            "dexnet.crop.size=16",
            *extra,
        ],
    )


def test_one_object_heap_scene_builds_renders_and_labels():
    from pipeline.dexnet.ood import connect, object_heap_scene, object_scene_rng

    cfg = _small_cfg("objects.min_count=4", "objects.max_count=4")
    sensor = conf_section("sensor")
    c = connect()
    try:
        scene = object_heap_scene(c, cfg, object_scene_rng(0, 0, 3), 12, sensor, 1e-4)
        again = object_heap_scene(c, cfg, object_scene_rng(0, 0, 3), 12, sensor, 1e-4)
    finally:
        p.disconnect(c)
    assert scene.depth_m.shape == scene.mask.shape == (160, 160)
    n = len(scene.heap.objects)
    assert 1 <= n <= 4 and scene.heap.num_dropped == 4
    assert set(np.unique(scene.mask)) <= set(range(n + 1)) and scene.mask.max() >= 1
    # depth as a generation shard stores it: whole multiples of 0.1 mm
    assert np.allclose(scene.depth_m / 1e-4, np.round(scene.depth_m / 1e-4), atol=1e-3)
    m = len(scene.candidates)
    assert 0 < m <= 12
    assert scene.crops.shape == (m, 1, 16, 16) and scene.crops.dtype == np.float16
    assert scene.poses.shape == (m, 2) and scene.quality.shape == scene.label.shape == (m,)
    assert np.array_equal(scene.label, scene.quality >= 0.5)
    assert set(scene.reason.tolist()) <= set(range(len(REASONS)))
    # the same generator gives the same scene
    assert np.array_equal(scene.depth_m, again.depth_m)
    assert np.array_equal(scene.quality, again.quality)


def test_bad_ood_config_is_refused_before_any_work(tmp_path):
    from pipeline.dexnet.ood import check_ood_config
    from pipeline.runtime.cli import compose
    from pipeline.stages.baseline import baseline

    base = ["experiment=smoke", f"paths.root={tmp_path}", "logging.progress=false"]
    with pytest.raises(ValueError, match="objects.families"):
        check_ood_config(compose("baseline", base + ["objects.families=[sphere]"]))
    with pytest.raises(ValueError, match="objects.min_count"):
        check_ood_config(compose("baseline", base + ["objects.min_count=0"]))
    with pytest.raises(ValueError, match="baseline.ood.num_scenes"):  # as the stage says it
        baseline(compose("baseline", base + ["baseline.ood.num_scenes=0"]))
    with pytest.raises(ValueError, match="gqcnn_ood"):  # unknown variant names the choices
        baseline(compose("baseline", base + ["baseline.variants=[gqcnn_odd]"]))
    assert not (tmp_path / "data" / "baseline").exists()


def test_ood_settings_are_in_the_version_only_with_the_variant():
    from pipeline.artifacts import stage_config
    from pipeline.runtime.cli import compose
    from pipeline.stages.baseline import NOT_AFFECTING_RESULT, SECTIONS

    cfg = compose("baseline", ["experiment=smoke"])
    assert "gqcnn_ood" in cfg.baseline.variants
    assert cfg.baseline.ood.num_scenes == cfg.generate.num_scenes  # as many heaps as boxes'
    assert "objects" not in stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)


def test_baseline_stage_with_the_ood_variant_end_to_end(smoke_pipeline, tmp_path):
    """The stage at a tiny scale: the object heaps' shards, the second GQ-CNN, its Table 2 row
    labelled with what it was trained on, the report's Table 2 showing it; a rerun reuses."""
    from pipeline.artifacts import load_manifest
    from pipeline.dataset.scenes import SceneDataset
    from pipeline.dexnet.planner import DexNetPlanner
    from pipeline.report.baseline import BaselineInfo, table2_table
    from pipeline.stages.baseline import baseline

    smoke = smoke_pipeline.copy(tmp_path / "root", tops=("data",))  # its generation artifact
    extra = [
        "baseline.train_version=none",
        "baseline.variants=[gqcnn_ood]",
        "baseline.ood.num_scenes=3",
        "baseline.ood.num_val_scenes=1",
        "baseline.ood.scenes_per_shard=2",
        "baseline.ood.candidates_per_scene=8",
        "objects.max_count=8",
        "baseline.workers=1",
        "baseline.log_samples=1",
        "baseline.epochs=1",
    ]
    cfg = smoke.cfg("baseline", *extra)
    out = baseline(cfg)
    m = load_manifest(out)
    assert sorted(p.name for p in (out / "ood").iterdir()) == [
        "train-00000.npz",
        "train-00001.npz",
        "val-00000.npz",
    ]
    labels = m["metrics"]["ood_candidate_labels"]
    assert labels["train"]["scenes"] == 3 and labels["val"]["scenes"] == 1
    assert 0 < labels["train"]["candidates"] <= 24
    assert sum(labels["train"]["contact_outcomes"].values()) == labels["train"]["candidates"]
    assert m["metrics"]["gqcnn_ood"]["train_samples"] == labels["train"]["candidates"]
    assert "objects" in m["config"] and m["config"]["baseline"]["ood"]["num_scenes"] == 3
    rows = {r["planner"]: r for r in m["metrics"]["table2"]["rows"]}
    assert rows["gqcnn_ood"]["name"].endswith("trained on non-box objects")
    assert rows["gqcnn_ood"]["images"] == len(SceneDataset(smoke.artifact("generate"), "test"))
    md = table2_table(BaselineInfo.load(out, m)).markdown()
    assert "Dex-Net-style GQ-CNN + CEM, trained on non-box objects" in md
    planner = DexNetPlanner.for_variant(cfg, "gqcnn_ood", np.eye(4), out)
    assert planner.net is not None
    assert baseline(cfg) == out  # reused
