"""Simulation figures: rendering, the rest check, generation and labelling throughput, the sensor
model."""

from __future__ import annotations

import dataclasses
import tempfile
import time

import numpy as np
import pybullet as p

from pipeline.tools.bench.common import BENCH_SEED, bench_scenes, intrinsics_of, rest_check_rng
from pipeline.tools.bench.planning import closed_loop_figures


def bare_loop(num_scenes: int, cfg, seed: int) -> float:
    """Scenes per second of a minimal settle + render loop (no storage, no logging).

    It draws the same heaps as the stage (same seeds, same order of random draws), drops them
    the same way, applies the same rest test (``pipeline.simulation.heap.settle``) and renders
    one frame with the configured renderer (``camera.renderer``), so the ratio of the two rates
    is the stage's overhead.
    """
    from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
    from pipeline.camera.render import render_depth
    from pipeline.simulation.heap import settle

    client = p.connect(p.DIRECT)
    intr = Intrinsics.from_config(cfg.camera)
    T_cam = camera_pose_above_bin(cfg.camera.height_above_bin_floor)
    sizes = [np.asarray(t.size) for t in cfg.boxes.types]
    b, ph = cfg.bin, cfg.physics
    lx, ly, h, t, ft = (
        b.inner_length_x,
        b.inner_width_y,
        b.wall_height,
        b.wall_thickness,
        b.floor_thickness,
    )
    parts = [
        ([lx / 2 + t, ly / 2 + t, ft / 2], [0, 0, -ft / 2]),
        ([t / 2, ly / 2 + t, (h + ft) / 2], [-(lx + t) / 2, 0, (h - ft) / 2]),
        ([t / 2, ly / 2 + t, (h + ft) / 2], [(lx + t) / 2, 0, (h - ft) / 2]),
        ([lx / 2, t / 2, (h + ft) / 2], [0, -(ly + t) / 2, (h - ft) / 2]),
        ([lx / 2, t / 2, (h + ft) / 2], [0, (ly + t) / 2, (h - ft) / 2]),
    ]
    hx, hy = lx / 2 - ph.drop_margin, ly / 2 - ph.drop_margin
    anchor = int(bool(ph.friction_anchor))
    t0 = time.perf_counter()
    for i in range(num_scenes):
        rng = np.random.default_rng([seed, 0, i])
        p.resetSimulation(physicsClientId=client)
        p.setGravity(0, 0, ph.gravity, physicsClientId=client)
        p.setPhysicsEngineParameter(
            fixedTimeStep=ph.time_step,
            numSolverIterations=ph.solver_iterations,
            physicsClientId=client,
        )
        # Ground: the same invisible 2 m slab as the stage (drawing it costs ~40 ms a frame).
        ground = p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[1, 1, 0.01], physicsClientId=client
        )
        plane = p.createMultiBody(
            0, ground, basePosition=[0, 0, -ft - 0.01], physicsClientId=client
        )
        p.changeVisualShape(plane, -1, rgbaColor=[1, 1, 1, 0], physicsClientId=client)
        static = []
        for half, pos in parts:
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
            static.append(p.createMultiBody(0, col, vis, basePosition=pos, physicsClientId=client))
        for body in [plane] + static:
            p.changeDynamics(body, -1, frictionAnchor=anchor, physicsClientId=client)
        bodies = []
        n = int(rng.integers(cfg.boxes.min_count, cfg.boxes.max_count + 1))
        for j in range(n):
            s = sizes[int(rng.integers(len(sizes)))]
            x, y = rng.uniform(-hx, hx), rng.uniform(-hy, hy)
            q = rng.normal(size=4)
            col = p.createCollisionShape(
                p.GEOM_BOX, halfExtents=(s / 2).tolist(), physicsClientId=client
            )
            vis = p.createVisualShape(
                p.GEOM_BOX, halfExtents=(s / 2).tolist(), physicsClientId=client
            )
            bodies.append(
                p.createMultiBody(
                    cfg.boxes.density * float(np.prod(s)),
                    col,
                    vis,
                    basePosition=[x, y, ph.drop_height_above_bin_floor],
                    baseOrientation=(q / np.linalg.norm(q)).tolist(),
                    physicsClientId=client,
                )
            )
            p.changeDynamics(bodies[-1], -1, frictionAnchor=anchor, physicsClientId=client)
            if j < n - 1:
                for _ in range(ph.drop_interval_steps):
                    p.stepSimulation(physicsClientId=client)
        settle(client, bodies, ph, ph.max_settle_steps)
        render_depth(
            client,
            intr,
            T_cam,
            cfg.camera.near,
            cfg.camera.far,
            ground=(-ft, plane),
            renderer=cfg.camera.renderer,
            bodies=static + bodies,
        )
    rate = num_scenes / (time.perf_counter() - t0)
    p.disconnect(client)
    return rate


def render_figures(cfg, num_heaps: int = 6, repeats: int = 5) -> dict[str, float]:
    """Both renderers on the same frames, interleaved in one run: ``num_heaps`` heaps of 20
    boxes, each seen from the generation camera and from two closed-loop-like close-up poses
    (``closeup_poses``). Median ms per 416 × 416 depth + mask frame of each and their ratio;
    the ray cast also as its numpy path (``render_reference``: the same bits without the
    compiled loops), with the compiled path's speed-up over it."""
    from pipeline.camera.geometry import Intrinsics, camera_pose_above_bin
    from pipeline.camera.raycast import boxes_from_pybullet
    from pipeline.camera.render import render_depth
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import drop_heap
    from pipeline.simulation.views import closeup_poses
    from pipeline.tools.bench import render_reference

    client = p.connect(p.DIRECT)
    intr = Intrinsics.from_config(cfg.camera)
    near, far = cfg.camera.near, cfg.camera.far
    boxes = dataclasses.replace(cfg.boxes, min_count=20, max_count=20)

    def numpy_path(T, ground):
        depth, ids = render_reference.raycast_boxes(boxes_from_pybullet(client), intr, T, near, far)
        render_reference.fill_ground(depth, ids, intr, T, ground[0], ground[1], far)

    def renderer(name):
        def draw(T, ground):
            render_depth(client, intr, T, near, far, ground=ground, renderer=name)

        return draw

    paths = {
        "tinyrenderer": renderer("tinyrenderer"),
        "raycast": renderer("raycast"),
        "raycast_numpy": numpy_path,
    }
    times: dict[str, list[float]] = {name: [] for name in paths}
    for i in range(num_heaps):
        cell = build_cell(client, cfg.bin, cfg.physics)
        heap = drop_heap(
            client, np.random.default_rng([BENCH_SEED, 5, i]), boxes, cfg.bin, cfg.physics
        )
        poses = [camera_pose_above_bin(cfg.camera.height_above_bin_floor)] + closeup_poses(
            heap.boxes, np.random.default_rng([BENCH_SEED, 6, i]), (0.15, 0.3)
        )
        ground = (-cfg.bin.floor_thickness, cell[0])
        for T in poses:
            for _ in range(repeats):
                for name, draw in paths.items():
                    t0 = time.perf_counter()
                    draw(T, ground)
                    times[name].append(time.perf_counter() - t0)
    p.disconnect(client)
    out = {f"render_{k}_ms_per_frame": 1000 * float(np.median(v)) for k, v in times.items()}
    out["render_raycast_speedup"] = (
        out["render_tinyrenderer_ms_per_frame"] / out["render_raycast_ms_per_frame"]
    )
    out["render_raycast_compiled_speedup"] = (
        out["render_raycast_numpy_ms_per_frame"] / out["render_raycast_ms_per_frame"]
    )
    n = len(times["raycast"]) // repeats
    print(
        f"render: {out['render_raycast_ms_per_frame']:.1f} ms per frame, "
        f"{out['render_raycast_speedup']:.1f}x TinyRenderer (same heaps, same run; "
        f"TinyRenderer {out['render_tinyrenderer_ms_per_frame']:.1f} ms; {n} frames of "
        f"{num_heaps} 20-box heaps, overhead and close-up poses, 416x416 depth + mask); "
        f"{out['render_raycast_compiled_speedup']:.2f}x its numpy path "
        f"({out['render_raycast_numpy_ms_per_frame']:.1f} ms, the same bits)"
    )
    return out


def rest_figures(cfg, num_heaps: int = 24) -> dict[str, float]:
    """Heaps of 20 boxes dropped as the generation stage drops them: settle steps, and how many
    heaps still have a box corner moving more than 2 mm in one more simulated second (the
    check of ``tests/test_generate.py::test_heaps_of_20_really_at_rest``, same seeds)."""
    from pipeline.cell.bin import build_cell
    from pipeline.simulation.heap import corner_drift, drop_heap

    client = p.connect(p.DIRECT)
    boxes = dataclasses.replace(cfg.boxes, min_count=20, max_count=20)
    steps, drift, capped = [], [], 0
    one_second = int(round(1.0 / cfg.physics.time_step))
    for i in range(num_heaps):
        build_cell(client, cfg.bin, cfg.physics)
        heap = drop_heap(client, rest_check_rng(i), boxes, cfg.bin, cfg.physics)
        steps.append(heap.settle_steps)
        capped += not heap.settled
        drift.append(float(corner_drift(client, [b.body_id for b in heap.boxes], one_second).max()))
    p.disconnect(client)
    moving = int(sum(d > 0.002 for d in drift))
    out = {
        "rest_heaps": num_heaps,
        "rest_heaps_moving_over_2mm": moving,
        "rest_worst_drift_mm": 1000 * max(drift),
        "rest_settle_steps_median": float(np.median(steps)),
        "rest_settle_steps_max": float(max(steps)),
        "rest_heaps_at_step_cap": capped,
    }
    print(
        f"heaps at rest: {num_heaps - moving} of {num_heaps} heaps of 20 boxes move no corner "
        f"more than 2 mm in one more second (worst {out['rest_worst_drift_mm']:.2f} mm); "
        f"settle steps median {out['rest_settle_steps_median']:.0f}, max "
        f"{out['rest_settle_steps_max']:.0f}; {capped} at the step cap"
    )
    return out


def stage_rates(
    num_scenes: int,
    root: str,
    executors: tuple[str, ...] = ("local",),
    workers_list: tuple[int, ...] = (1, 2),
    extra: tuple[str, ...] = (),
    label: bool = True,
) -> dict[str, float]:
    """Scenes per second of ``pipeline.stages.generate`` and ``pipeline.stages.label`` with 1 and 2
    workers (simulation + storage; labelling = surfaces + hand + robot checks), from the manifests.
    Keys ``generate_2w_scenes_per_s`` (local executor), ``generate_ray_2w_scenes_per_s`` (ray:
    run with Ray already started, so its start-up is not counted)."""
    from pipeline.artifacts.store import load_manifest
    from pipeline.runtime.cli import compose
    from pipeline.stages.generate import generate
    from pipeline.stages.label import label as label_stage

    def cfg(stage: str, workers: int, sub: str, executor: str = "local"):
        return compose(
            stage,
            [
                f"executor={executor}",
                "experiment=smoke",
                f"paths.root={root}/{sub}",
                f"generate.num_scenes={num_scenes}",
                "generate.num_val_scenes=0",
                "generate.num_test_scenes=0",
                "generate.scenes_per_shard=10",
                f"generate.workers={workers}",
                f"label.workers={workers}",
                "logging.max_logged_scenes=0",
                "logging.progress=false",
                f"seed={BENCH_SEED}",
                *extra,
            ],
        )

    out = {}
    for executor, workers in [(e, w) for e in executors for w in workers_list]:
        key = f"{workers}w" if executor == "local" else f"{executor}_{workers}w"
        gen = load_manifest(generate(cfg("generate", workers, key, executor)))
        out[f"generate_{key}_scenes_per_s"] = gen["timings"]["scenes_per_s"]
        if not label:
            continue
        lab = load_manifest(label_stage(cfg("label", workers, key, executor)))
        out[f"label_{key}_scenes_per_s"] = lab["timings"]["scenes_per_s"]
        if workers == 1 and executor == "local":
            out["label_surfaces_ms_per_scene"] = (
                1000 * lab["timings"]["surface_detection_s_per_scene"]
            )
            out["label_robot_ms_per_scene"] = 1000 * lab["timings"]["robot_checks_s_per_scene"]
    return out


def render_group(cfg, num_scenes: int) -> dict[str, float]:
    """``--only render``: both renderers on the same frames, the rest check, generation scenes/s
    (stage, 1 worker, and the bare loop) and the closed loop with each renderer (one trial of
    the evaluation's size, the planarity planner, one process)."""
    from pipeline.runtime.cli import compose

    out = render_figures(cfg)
    out.update(rest_figures(cfg))
    # best of two alternating runs of each: on a shared 2-core machine single runs of a few
    # seconds scatter by about ±15 %
    for _rep in range(2):
        for name in ("tinyrenderer", "raycast"):
            rc = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, renderer=name))
            with tempfile.TemporaryDirectory() as root:
                rates = stage_rates(
                    num_scenes,
                    root,
                    workers_list=(1,),
                    extra=(f"camera.renderer={name}",),
                    label=False,
                )
            for key, rate in (
                (f"generate_1w_scenes_per_s_{name}", rates["generate_1w_scenes_per_s"]),
                (f"bare_loop_scenes_per_s_{name}", bare_loop(num_scenes, rc, BENCH_SEED)),
            ):
                out[key] = max(out.get(key, 0.0), rate)
    for name in ("tinyrenderer", "raycast"):
        out[f"stage_vs_bare_{name}"] = (
            out[f"generate_1w_scenes_per_s_{name}"] / out[f"bare_loop_scenes_per_s_{name}"]
        )
        print(
            f"generation ({name}), 1 worker, best of 2: "
            f"{out[f'generate_1w_scenes_per_s_{name}']:.2f} scenes/s; bare loop "
            f"{out[f'bare_loop_scenes_per_s_{name}']:.2f} scenes/s; stage / bare "
            f"{out[f'stage_vs_bare_{name}']:.2f} (target >= 0.90)"
        )
    out["generate_raycast_speedup"] = (
        out["generate_1w_scenes_per_s_raycast"] / out["generate_1w_scenes_per_s_tinyrenderer"]
    )
    print(f"generation speed-up of the ray-cast renderer: {out['generate_raycast_speedup']:.2f}x")
    boxes = int(compose("evaluate", ["experiment=default"]).evaluate.boxes_per_trial)
    for name in ("tinyrenderer", "raycast"):
        out.update(closed_loop_figures(renderer=name, descriptor=False, boxes=boxes))
    out["closed_loop_raycast_speedup"] = (
        out["sim_s_per_wall_s_raycast"] / out["sim_s_per_wall_s_tinyrenderer"]
    )
    print(
        f"closed-loop speed-up of the ray-cast renderer: "
        f"{out['closed_loop_raycast_speedup']:.2f}x (target: >= 2 simulated s per wall s)"
    )
    return out


def sensor_figures(num_images: int = 20, repeats: int = 3) -> dict[str, float]:
    """The SR300 model and the depth filters on the bench's heaps: ms per 416 × 416 image
    (median over images × repeats), the fraction of pixels without data where the ideal depth
    has data, and the error against the ideal depth (median |e| and the 90th percentile of
    |e|, mm, over the pixels with data). The incidence angles, the model's costliest step, are
    also timed with their numpy path (``sensor_reference``), interleaved with the compiled loop
    on the same images, with the ratio and whether both gave the same bits."""
    from omegaconf import OmegaConf

    from pipeline.camera.depth_filter import fill_holes, median_filter, preprocess_depth
    from pipeline.camera.sensor import apply_sensor_model, incidence_angles
    from pipeline.runtime.cli import compose
    from pipeline.tools.bench import sensor_reference

    cfg = OmegaConf.to_object(compose("generate", ["experiment=default", "sensor=sr300"]))
    filters = {
        name: OmegaConf.to_object(compose("evaluate", [f"depth_filter={name}"])).depth_filter
        for name in ("fill", "fill_median")
    }
    intr = intrinsics_of(cfg)
    scenes = bench_scenes(cfg, num_images)
    times: dict[str, list[float]] = {
        "sensor": [],
        "fill": [],
        "median5": [],
        "incidence_compiled": [],
        "incidence_numpy": [],
    }
    same = True
    stats: dict[str, list[np.ndarray]] = {"sensor": [], "fill": [], "fill_median": []}
    lost: dict[str, list[float]] = {k: [] for k in stats}
    for k, sc in enumerate(scenes):
        ideal = sc.depth_clean_m
        for r in range(repeats):
            rng = np.random.default_rng([BENCH_SEED, k, r])
            t0 = time.perf_counter()
            noisy = apply_sensor_model(ideal, cfg.sensor, rng, intr)
            t1 = time.perf_counter()
            filled = fill_holes(noisy, filters["fill"].fill_holes_px)
            t2 = time.perf_counter()
            median_filter(filled, filters["fill_median"].median_px)
            t3 = time.perf_counter()
            times["sensor"].append(t1 - t0)
            times["fill"].append(t2 - t1)
            times["median5"].append(t3 - t2)
            t0 = time.perf_counter()
            fast = incidence_angles(ideal, intr)
            t1 = time.perf_counter()
            slow = sensor_reference.incidence_angles(ideal, intr)
            t2 = time.perf_counter()
            times["incidence_compiled"].append(t1 - t0)
            times["incidence_numpy"].append(t2 - t1)
            same = same and fast.tobytes() == slow.tobytes()
        images = {
            "sensor": noisy,
            "fill": preprocess_depth(noisy, filters["fill"]),
            "fill_median": preprocess_depth(noisy, filters["fill_median"]),
        }
        for name, img in images.items():
            has = ideal > 0
            lost[name].append(float(np.mean((img == 0) & has)))
            ok = has & (img > 0)
            stats[name].append(np.abs(img[ok] - ideal[ok]))
    out = {f"{k}_ms_per_image": 1000 * float(np.median(v)) for k, v in times.items()}
    out["incidence_speedup"] = out["incidence_numpy_ms_per_image"] / max(
        out["incidence_compiled_ms_per_image"], 1e-9
    )
    out["incidence_same_bits"] = float(same)
    for name in stats:
        err = np.concatenate(stats[name])
        out[f"{name}_missing_fraction"] = float(np.mean(lost[name]))
        out[f"{name}_median_abs_error_mm"] = 1000 * float(np.median(err))
        out[f"{name}_p90_abs_error_mm"] = 1000 * float(np.percentile(err, 90))
    print(
        f"SR300 model and depth filters, {num_images} default heaps x {repeats} noise draws "
        "(416 x 416):"
    )
    print(
        f"  time per image: sensor model {out['sensor_ms_per_image']:.1f} ms, hole filling "
        f"{out['fill_ms_per_image']:.1f} ms, 5x5 median {out['median5_ms_per_image']:.1f} ms"
    )
    print(
        f"  incidence angles: compiled {out['incidence_compiled_ms_per_image']:.2f} ms, numpy "
        f"path {out['incidence_numpy_ms_per_image']:.1f} ms per image "
        f"({out['incidence_speedup']:.0f}x; same bits: {bool(same)})"
    )
    for name in stats:
        print(
            f"  {name:12s} pixels without data {100 * out[f'{name}_missing_fraction']:5.1f} %, "
            f"|error| median {out[f'{name}_median_abs_error_mm']:.2f} mm, "
            f"90th percentile {out[f'{name}_p90_abs_error_mm']:.2f} mm"
        )
    return out
