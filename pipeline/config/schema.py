"""Typed configuration schema for every stage.

Every stage composes the same :class:`PipelineConfig`; each stage hashes only the sections it
reads (see ``pipeline.artifacts.version``) so that, for example, changing ``report.*`` does not
change the generation artifact's version.

Values live in ``conf/``: one YAML file per physical set-up (camera, bin, box set, physics,
sensor), one per stage section (``stage/<stage>.yaml``, in every stage's config) and one per
experiment scale (``experiment/smoke|default|paper``). The fields here have no defaults
(``MISSING``): every value has one home, its YAML file, and a key that no YAML file sets is an
error when it is read. The schema gives the types (a wrong type in YAML or on the command line
is refused) and, in comments, the units.

Units: metres, kilograms, seconds, pixels. Frames: world (z up, origin at the centre of the bin
floor's top surface), camera (OpenCV: x right, y down, z forward along the optical axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING


@dataclass
class PathsConfig:
    """Where artifacts go. ``root`` holds ``data/``, ``models/`` and ``reports/``."""

    root: str = MISSING  # set in conf/paths/default.yaml to the repository root
    data: str = MISSING
    models: str = MISSING
    reports: str = MISSING


@dataclass
class CameraConfig:
    """Pinhole depth camera (SR300-like), OpenCV convention.

    ``fx, fy, cx, cy`` are in pixels for a ``width`` × ``height`` image; pixel (u, v) = (0, 0)
    is the centre of the top-left pixel. ``height_above_bin_floor`` is the distance from the
    optical centre to the bin floor's top surface, along the (vertical) optical axis.
    """

    name: str = MISSING
    width: int = MISSING
    height: int = MISSING
    fx: float = MISSING
    fy: float = MISSING
    cx: float = MISSING
    cy: float = MISSING
    height_above_bin_floor: float = MISSING
    near: float = MISSING
    far: float = MISSING
    renderer: str = MISSING  # "raycast" | "tinyrenderer" (pipeline.camera.render)


@dataclass
class BinConfig:
    """An open box (tote) standing on the ground, centred on the world origin."""

    inner_length_x: float = MISSING
    inner_width_y: float = MISSING
    wall_height: float = MISSING
    wall_thickness: float = MISSING
    floor_thickness: float = MISSING
    lateral_friction: float = MISSING


@dataclass
class BoxType:
    """A cuboid of edge lengths ``size`` = (x, y, z) in metres."""

    name: str = MISSING
    size: List[float] = MISSING


@dataclass
class CartonsConfig:
    """A continuous distribution of cartons (``pipeline.simulation.cartons``): edges from ranges,
    density from a range, mass capped at the hand's payload, held-out sizes carved out. Metres,
    kg/m³, kg."""

    long_edge: List[float] = MISSING  # [low, high] of the longest edge, m
    middle_ratio: List[float] = MISSING  # [low, high] of middle / long
    short_ratio: List[float] = MISSING  # [low, high] of short / middle
    min_edge: float = MISSING  # m: a thinner carton is drawn again
    density: List[float] = MISSING  # [low, high], kg/m³
    max_mass: float = MISSING  # kg (the hand's payload)
    held_out: List[List[float]] = MISSING  # sizes (m) kept outside the distribution ...
    held_out_margin: float = MISSING  # ... with every sorted edge within this fraction of theirs


@dataclass
class BoxesConfig:
    """The box set that heaps are drawn from (uniformly over ``types``; with ``cartons``, the
    splits of ``generate.carton_splits`` draw every box from that distribution instead)."""

    name: str = MISSING
    types: List[BoxType] = MISSING
    cartons: Optional[CartonsConfig] = MISSING  # None: every box from types
    density: float = MISSING  # kg/m^3
    lateral_friction: float = MISSING
    min_count: int = MISSING
    max_count: int = MISSING


@dataclass
class ObjectsConfig:
    """Random convex non-box objects (``conf/objects/``): the out-of-domain training heaps of the
    Dex-Net-style baseline. The shape keys are ``pipeline.simulation.objects.ObjectSetSpec``'s
    fields (ranges are [low, high], m); the rest are the heap's, as ``BoxesConfig``'s."""

    name: str = MISSING
    families: List[str] = MISSING  # cylinder | prism | hull, each equally likely
    cylinder_radius: List[float] = MISSING
    cylinder_length: List[float] = MISSING
    cylinder_sections: int = MISSING
    prism_sides: List[int] = MISSING
    prism_radius: List[float] = MISSING
    prism_length: List[float] = MISSING
    prism_regular_share: float = MISSING
    prism_jitter: float = MISSING
    prism_squeeze: List[float] = MISSING
    hull_semi_axis: List[float] = MISSING
    hull_points: List[int] = MISSING
    density: float = MISSING  # kg/m^3
    lateral_friction: float = MISSING
    min_count: int = MISSING  # objects per heap, uniform, inclusive
    max_count: int = MISSING


@dataclass
class BaselineOODConfig:
    """The out-of-domain GQ-CNN's training heaps (``baseline.ood``; variant ``gqcnn_ood``)."""

    num_scenes: int = MISSING  # training heaps of ``objects``
    num_val_scenes: int = MISSING  # validation heaps of ``objects``
    scenes_per_shard: int = MISSING
    candidates_per_scene: int = MISSING


@dataclass
class PhysicsConfig:
    """pybullet settings and the rest criterion (see docs/simulation.md)."""

    time_step: float = MISSING
    solver_iterations: int = MISSING
    gravity: float = MISSING
    drop_height_above_bin_floor: float = MISSING
    drop_interval_steps: int = MISSING  # "trickle": one box every N steps
    drop_margin: float = MISSING  # keep drop xy this far inside the bin walls
    friction_anchor: bool = MISSING  # Bullet friction anchors on every box and bin part
    rest_check_interval_steps: int = MISSING
    rest_window_steps: int = MISSING  # at rest: over this many steps ...
    rest_corner_displacement: float = MISSING  # m: ... no box corner moved farther than this
    max_settle_steps: int = MISSING


@dataclass
class SensorConfig:
    """Depth-sensor model applied after rendering (``enabled: false`` = ideal depth).

    See ``pipeline.camera.sensor`` for the model and ``conf/sensor/sr300.yaml`` for the
    parameters' sources. Metres and degrees.
    """

    name: str = MISSING
    enabled: bool = MISSING
    noise_sigma_0: float = MISSING  # m, σ(z, θ) = σ0 + σ2·z² + σθ/√z · θ²/(π/2 − θ)²
    noise_sigma_2: float = MISSING  # m per m²
    noise_sigma_theta: float = MISSING  # m·√m
    projector_baseline: float = MISSING  # m along the camera's x axis (0 = no projector shadow)
    dropout_angle_start_deg: float = MISSING  # steep-surface dropout starts at this incidence angle
    dropout_angle_deg: float = MISSING  # ... and is certain from this one (90 = off)
    min_range: float = MISSING  # m: no data nearer than this
    max_range: float = MISSING  # m: no data beyond this
    edge_jump: float = MISSING  # m: a depth step between 4-neighbours
    edge_dropout_prob: float = MISSING  # chance a pixel at a depth step is lost
    quantisation_step: float = MISSING  # m (0 = none)
    hole_rate: float = MISSING  # share of the image lost in blobs of hole_size_px (0 = none)
    hole_size_px: int = MISSING  # side of a hole blob, pixels
    depth_bias: float = MISSING  # m added to every depth (calibration offset)
    depth_scale_error: float = MISSING  # depth × (1 + this) (calibration scale error)


@dataclass
class DepthFilterConfig:
    """Depth preprocessing before the planners (``pipeline.camera.depth_filter``); 0 = off."""

    name: str = MISSING
    fill_holes_px: int = MISSING  # fill holes from the farthest neighbour, this many 3 x 3 passes
    median_px: int = MISSING  # median kernel (3 or 5) after filling


@dataclass
class CameraRandomisationConfig:
    """Training depth through randomised sensor models (``pipeline.camera.randomise``): in the
    splits ``splits``, a scene keeps the ideal depth with probability ``ideal_fraction``, else
    each sensor parameter is drawn uniformly from its [low, high] range here (the others are
    ``sensor``'s SR300-class values' keys: see ``SensorConfig``)."""

    enabled: bool = MISSING
    splits: List[str] = MISSING
    ideal_fraction: float = MISSING
    noise_sigma_0: List[float] = MISSING
    noise_sigma_2: List[float] = MISSING
    noise_sigma_theta: List[float] = MISSING
    projector_baseline: List[float] = MISSING
    dropout_angle_start_deg: List[float] = MISSING
    dropout_angle_span_deg: List[float] = MISSING  # dropout_angle_deg = start + this
    edge_dropout_prob: List[float] = MISSING
    quantisation_step: List[float] = MISSING
    hole_rate: List[float] = MISSING
    hole_size_px: List[int] = MISSING
    depth_bias: List[float] = MISSING
    depth_scale_error: List[float] = MISSING
    min_range: float = MISSING  # m, fixed (as SensorConfig's)
    max_range: float = MISSING  # m, fixed
    edge_jump: float = MISSING  # m, fixed


@dataclass
class GenerateConfig:
    """The generation stage: heaps per split, storage, parallelism."""

    num_scenes: int = MISSING  # training scenes; validation and test are given separately
    num_val_scenes: int = MISSING
    num_test_scenes: int = MISSING
    scenes_per_shard: int = MISSING
    depth_unit: float = MISSING  # stored depth = round(depth_m / depth_unit) as uint16 (0 = no data)
    size_jitter: float = MISSING  # each box edge scaled by U(1 - j, 1 + j) in size_jitter_splits
    size_jitter_splits: List[str] = MISSING  # splits whose boxes are jittered (others: exact sizes)
    carton_splits: List[str] = MISSING  # splits whose boxes come from boxes.cartons (when set)
    camera_randomisation: CameraRandomisationConfig = field(
        default_factory=CameraRandomisationConfig)
    workers: int = MISSING  # 0 = all cores; does not change the artifact
    force: bool = MISSING  # recompute even if this version exists


@dataclass
class HandConfig:
    """The two-cup suction hand (paper Fig. 1b) and the hand-level fit criteria, metres."""

    cup_diameter: float = MISSING
    cup_offset: float = MISSING  # cup centre to camera centre along the hand's Y
    standoff: float = MISSING  # d*: camera to surface along the normal at the target pose
    margin: float = MISSING  # a cup disc grown by this must lie inside the visible surface
    min_area_ratio: float = MISSING  # surface area >= ratio × the active cups' area
    tie_tolerance: float = MISSING  # L/R camera heights closer than this: a tie (→ L)
    # hand rotations about the normal tried by the robot-level checks, in order (0 = paper)
    rotations_deg: List[float] = MISSING
    # labels: a pattern whose cups would not hold the box's weight (the suction hold test) is NG
    hold_check: bool = MISSING
    payload_kg: float = MISSING  # the heaviest box the hand is meant to lift (both cups)


@dataclass
class SurfaceConfig:
    """Surface detection by RANSAC plane fits on per-object point clusters."""

    distance_threshold: float = MISSING  # RANSAC inlier distance, m
    ransac_backend: str = MISSING  # "numpy" (seeded, deterministic) or "open3d" (segment_plane)
    ransac_n: int = MISSING
    num_iterations: int = MISSING
    min_inliers: int = MISSING  # fewer points: not a surface
    search_min_inliers: int = MISSING  # the plane search stops with fewer points left
    max_surfaces_per_object: int = MISSING
    seed: int = MISSING  # the numpy backend's RANSAC generator
    ransac_max_points: int = MISSING
    refine_iterations: int = MISSING
    connectivity: int = MISSING  # 4 or 8
    truth_min_visible_px: int = MISSING  # ground-truth faces with fewer visible pixels are ignored
    match_max_center_dist: float = MISSING  # m, detected ↔ true face matching
    match_max_normal_deg: float = MISSING


@dataclass
class PathSchema:
    """The path check's sampling (``pipeline.robot.path.PathCheckConfig`` documents each field)."""

    step_m: float = MISSING
    step_deg: float = MISSING
    bin_clearance: float = MISSING


@dataclass
class RobotSchema:
    """The 7-DoF robot (``pipeline.robot.RobotConfig`` documents each field)."""

    base_position: List[float] = MISSING
    base_yaw_deg: float = MISSING
    pedestal_half_size_xy: float = MISSING
    home_camera_height: float = MISSING
    ik_max_iterations: int = MISSING
    ik_residual_threshold: float = MISSING
    ik_joint_damping: float = MISSING
    ik_hand_damping: float = MISSING
    ik_refinements: int = MISSING
    ik_restarts: int = MISSING
    ik_restart_noise_rad: float = MISSING
    position_tolerance: float = MISSING
    orientation_tolerance_deg: float = MISSING
    collision_margin: float = MISSING
    self_collision_margin: float = MISSING
    path_check: bool = MISSING  # check the approach path, not only the grasp pose
    path: PathSchema = MISSING  # how the path is sampled (``pipeline.robot.path.PathCheckConfig``)


@dataclass
class LabelConfig:
    """The labelling stage."""

    generate_version: str = MISSING
    robot_checks: bool = MISSING  # robot-level labels (IK, joint limits, collisions)
    single_cup_fallback: bool = MISSING  # a B the robot cannot take is labelled L or R if one can
    hold_mass: str = MISSING  # own | heaviest: the mass the hold check weighs a carton at
    workers: int = MISSING  # 0 = all cores; does not change the artifact
    force: bool = MISSING


@dataclass
class ModelConfig:
    """The grasp-point DCNN (``pipeline.planner.network.NetworkConfig`` documents each field)."""

    name: str = MISSING
    width: float = MISSING  # channel multiplier on Darknet-19 widths (1.0 = the paper's network)
    grid: int = MISSING  # N
    input_size: int = MISSING
    num_classes: int = MISSING
    leaky_slope: float = MISSING


@dataclass
class RankingSchema:
    """The ranking stored with the model (``pipeline.planner.ranking.RankingConfig`` documents
    each field; its angles here in degrees)."""

    phi_switch_deg: float = MISSING  # Eq. 7: J_inclination from this inclination on
    normal_half_window: int = MISSING  # h: the normal is averaged over (2h + 1)^2 pixels
    max_depth_jump: float = MISSING  # m: a larger depth step to a neighbour is an object edge
    policy: str = MISSING  # "paper" (Eq. 7) | "height_tiebreak" (Sec. 8.4's proposed fix)
    inclination_tie_deg: float = MISSING  # height_tiebreak: inclinations closer than this tie


@dataclass
class ScheduleSchema:
    """``train.schedule`` (``pipeline.planner.schedule.ScheduleConfig`` documents each field)."""

    name: str = MISSING  # "constant" (the paper) | "onecycle"
    max_lr: float = MISSING  # onecycle: the peak rate
    warmup_fraction: float = MISSING  # onecycle: share of the steps rising to max_lr
    div_factor: float = MISSING  # onecycle: first rate = max_lr / div_factor
    final_div_factor: float = MISSING  # onecycle: last rate = first rate / final_div_factor


@dataclass
class TrainConfig:
    """The training stage (``pipeline.train``) and what it stores for the planner."""

    label_version: str = MISSING
    epochs: int = MISSING  # the most epochs; fewer when validation-based stopping ends it
    patience: int = MISSING  # stop after this many epochs without a lower val loss (0: never)
    batch_size: int = MISSING  # paper Sec. 6
    lr: float = MISSING  # Adam, paper Sec. 6 (the constant schedule's rate)
    schedule: ScheduleSchema = MISSING  # the rate over the run (``pipeline.planner.schedule``)
    betas: List[float] = MISSING
    alpha: float = MISSING  # focal loss, Sec. 4.1
    gamma: float = MISSING
    lambda_coord: float = MISSING
    lambda_class: float = MISSING
    depth_scale: float = MISSING  # m: input = (depth - D_ground) / depth_scale
    missing_depth_value: float = MISSING  # network input where depth = 0 (no data)
    augment_flip: str = MISSING  # "none" | "u" (horizontal) | "v" (vertical) | "uv"
    max_train_images: int = MISSING  # 0 = the whole train split
    channels_last: bool = MISSING  # train in the channels-last memory layout (faster on CPU)
    threshold: Optional[float] = MISSING  # th of Eq. 3; None: calibrated on val (planner.calibration)
    threshold_grid: List[float] = MISSING  # th values calibration scores (conf)
    match_radius_px: float = MISSING  # Table 1: a prediction within this of a same-class truth
    ranking: RankingSchema = MISSING  # Eqs. 7-10 (``pipeline.planner.ranking.RankingConfig``)
    num_threads: int = MISSING  # torch CPU threads (fixed: results depend on it); split among DDP ranks
    loader_workers: int = MISSING  # processes decoding batches (0 = the training process); result-neutral
    device: str = MISSING  # "auto" (CUDA when available) | "cpu" | "cuda"
    log_samples: int = MISSING  # test images logged with their predictions
    force: bool = MISSING


@dataclass
class SuctionSchema:
    """The suction contact model (``pipeline.dexnet.contact.SuctionModelConfig`` documents each
    field). The cup radius comes from ``hand.cup_diameter``; box density from ``boxes.density``."""

    vacuum_force: float = MISSING  # N per cup
    friction: float = MISSING
    compliance: float = MISSING  # m
    ring_points: int = MISSING
    visibility_tolerance: float = MISSING  # m
    perturbations: int = MISSING
    sigma_position: float = MISSING  # m
    sigma_axis_deg: float = MISSING
    quality_threshold: float = MISSING


@dataclass
class CropSchema:
    """The GQ-CNN's crop and pose input (``pipeline.dexnet.gqcnn.CropConfig`` documents each
    field; D_ground comes from ``camera`` and ``bin``)."""

    window_px: int = MISSING  # crop of the depth image around a candidate, pixels
    size: int = MISSING  # the crop resized to this (GQ-CNN input), pixels
    depth_scale: float = MISSING  # m: crop input = (depth - candidate depth) / scale
    missing_value: float = MISSING  # crop input where depth = 0 (no data)
    pose_depth_scale: float = MISSING  # m: pose input = (candidate depth - D_ground) / scale


@dataclass
class PlanaritySchema:
    """The analytic disc-planarity quality (``pipeline.dexnet.quality.PlanarityConfig``; the cup
    radius comes from ``hand.cup_diameter``)."""

    sigma: float = MISSING  # m
    min_coverage: float = MISSING


@dataclass
class DexNetSchema:
    """The Dex-Net-style planner: sampler, cross-entropy method, GQ-CNN, analytic quality."""

    border_px: int = MISSING
    max_approach_angle_deg: float = MISSING
    max_tries: int = MISSING
    sobel_ksize: int = MISSING
    num_seed_samples: int = MISSING
    num_gmm_samples: int = MISSING
    num_iters: int = MISSING
    gmm_refit_p: float = MISSING
    gmm_component_frac: float = MISSING
    gmm_reg_covar: float = MISSING
    max_resamples: int = MISSING
    crop: CropSchema = MISSING  # the GQ-CNN's input (``pipeline.dexnet.gqcnn.CropConfig``)
    width: int = MISSING  # channels of the first conv layer (doubled per block)
    fc: int = MISSING
    planarity: PlanaritySchema = MISSING  # the analytic variant (``dexnet.quality.PlanarityConfig``)
    object_margin: float = MISSING  # m: object mask = depth at least this above the bin floor


@dataclass
class BaselineConfig:
    """The comparison stage (``pipeline.baseline``): GQ-CNN training and Table 2."""

    generate_version: str = MISSING
    train_version: str = MISSING  # the project's planner for Table 2; "none" leaves it out
    candidates_per_scene: int = MISSING  # sampled and labelled per training / validation scene
    max_train_scenes: int = MISSING  # 0 = the whole train split
    epochs: int = MISSING
    batch_size: int = MISSING
    lr: float = MISSING
    weight_decay: float = MISSING
    num_threads: int = MISSING
    variants: List[str] = MISSING
    ood: BaselineOODConfig = MISSING  # the gqcnn_ood variant's training heaps (``objects``)
    max_eval_images: int = MISSING  # 0 = the whole test split
    table2_radius_px: float = MISSING
    curve_min_px: int = MISSING
    curve_max_px: int = MISSING
    log_samples: int = MISSING
    workers: int = MISSING
    force: bool = MISSING


@dataclass
class MotionSchema:
    """Robot speed limits and the timing of the pick sequence (``conf/motion/``)."""

    max_joint_speed: float = MISSING  # rad/s per joint (xArm6: 180 deg/s)
    max_joint_accel: float = MISSING  # rad/s^2, for the point-to-point move times
    approach_speed: float = MISSING  # m/s along the camera axis, from d* to contact
    press_depth: float = MISSING  # m, cups pressed this far past the surface
    lift_height: float = MISSING  # m, straight up with the box
    lift_speed: float = MISSING  # m/s
    suction_on_s: float = MISSING  # vacuum build-up before lifting
    suction_off_s: float = MISSING  # release at the conveyor
    place_position: List[float] = MISSING  # m, world: camera above the conveyor
    pregrasp_standoff: float = MISSING  # m, the pre-grasp's largest distance along the normal
    pregrasp_wall_margin: float = MISSING  # m, camera and cup lips this far inside the walls
    pregrasp_image_fraction: float = MISSING  # lift: the centre within this share of the half-FOV
    approach: str = MISSING  # "lift" | "pregrasp" | "direct" (the paper: straight to d*)
    via_tolerance_scale: float = MISSING  # the first goal counts as reached within this x servo tolerances


@dataclass
class ServoSchema:
    """Surface feature descriptor (Eqs. 11-14) and 2.5D visual servoing (Eqs. 15-28)."""

    window: int = MISSING
    window_tolerance_depth: float = MISSING  # m; > 0: window RANSAC tolerance ε1·min(1, Z/this)
    seed_repair: bool = MISSING  # crack and small-component repairs of the seed
    track_normal_deg: float = MISSING  # servo: stay on the surface of the previous frame's normal
    track_offset_m: Optional[float] = MISSING  # servo: ... and within this of its plane (m)
    eps_distance: float = MISSING
    eps_normal: float = MISSING
    min_pixels: int = MISSING
    connectivity: int = MISSING
    window_hypotheses: int = MISSING
    window_refits: int = MISSING
    rim: int = MISSING
    refine: bool = MISSING
    gain: float = MISSING  # lambda
    gain_per_step: bool = MISSING
    max_linear_speed: float = MISSING  # m/s, camera, during visual servoing
    max_angular_speed: float = MISSING  # rad/s
    uniform_clamp: bool = MISSING  # one clamp factor for V and Omega
    control_rate_hz: float = MISSING
    tolerance_xy: float = MISSING
    tolerance_log_z: float = MISSING
    tolerance_rot_deg: float = MISSING
    timeout_s: float = MISSING
    joint_damping: float = MISSING
    normal_smoothing: int = MISSING  # descriptor: average n_p over (2k+1)^2 pixels (noisy depth)


@dataclass
class HeapModelSchema:
    """The robot's heap model from depth (``pipeline.controller.heap_model``), metres."""

    cell_m: float = MISSING  # grid cell side (and the robot's surface points' spacing)
    bin_tolerance_m: float = MISSING  # points this near the bin's floor or inner walls are the bin
    flying_tolerance_m: float = MISSING  # neighbours within this depth agree (0: no flying-pixel step)
    flying_min_neighbours: int = MISSING  # a pixel needs this many agreeing neighbours of its 8


@dataclass
class EvaluateConfig:
    """The closed-loop evaluation stage (``pipeline.evaluate``)."""

    planners: List[str] = MISSING  # built-in names, or plug-ins (package.module:Class, entry points)
    split: str = MISSING  # dev | test: which stream of heaps (docs/closed_loop.md, "Splits")
    # what the run-time check knows of the heap: observed (its depth image) | truth (ablation)
    collision_model: str = MISSING
    heap_model: HeapModelSchema = field(default_factory=HeapModelSchema)
    dexnet_variant: str = MISSING  # gqcnn | gqcnn_ood | planarity (a baseline variant)
    dexnet_pattern: str = MISSING  # the cup that serves Dex-Net's single suction point
    dcnn_threshold: Optional[float] = MISSING  # th of Eq. 3 for the closed loop; None: the model's
    dcnn_fallback_ratio: Optional[float] = MISSING  # second tier above this times th; None: off
    stop_on_box_contact: bool = MISSING  # True: touching any box but the target fails the attempt
    check_reachability: bool = MISSING  # run-time robot-level check of the planned grasp
    max_candidates_checked: int = MISSING
    # m: the check first asks this clearance from the bin on the servo's path; None: off
    preferred_bin_clearance: Optional[float] = MISSING
    retry_policy: str = MISSING  # "skip_failed" | "repeat" (the plain protocol)
    retry_same_point_m: float = MISSING
    retry_neighbour_m: float = MISSING  # m: the heap this near the failed point is its surroundings
    retry_depth_change_m: float = MISSING  # m: a larger depth change is a change
    retry_changed_area_m2: float = MISSING  # m²: this much changed area near the point: changed
    # after these outcomes every pattern at the failed point is skipped, not only the failed one
    retry_point_outcomes: List[str] = MISSING
    retry_drop_single_cup: bool = MISSING  # after a single cup dropped a box: no single cup there
    retry_no_seal_two_cups: bool = MISSING  # after B found no seal: no B there for the trial
    face_split_m: float = MISSING  # split the home region at other planner points this far away
    check_hand_fit: bool = MISSING  # the run-time check tests the pattern's cups on the surface
    single_cup_fallback: bool = MISSING  # a rejected B is tried with L, then R
    min_area_ratio: float = MISSING  # 0: off (paper); 1.2: Sec. 8.4's surface-area safety check
    label_no_grasp: bool = MISSING  # a "no grasp" end also asks the labels on that frame
    train_version: str = MISSING
    baseline_version: str = MISSING
    num_trials: int = MISSING
    boxes_per_trial: int = MISSING
    max_failures_per_target: int = MISSING
    max_attempts_per_trial: int = MISSING
    num_threads: int = MISSING
    log_trials: int = MISSING
    workers: int = MISSING
    force: bool = MISSING


@dataclass
class ClosedLoopVariant:
    """One closed-loop run of the robustness study: a network and evaluate-stage overrides."""

    name: str = MISSING
    model: str = MISSING  # clean | noisy: the network trained on ideal / on the sensor's depth
    # dev: robustness.closed_loop_trials trials on the dev heaps; test: evaluate.num_trials on
    # the test heaps (the headline row)
    split: str = MISSING
    overrides: List[str] = MISSING


@dataclass
class RobustnessConfig:
    """The robustness study (``pipeline.robustness``)."""

    sensor: str = MISSING
    noisy_network: bool = MISSING  # also train a network on the sensor's depth (a second one)
    train_version: str = MISSING  # the network under test ("latest" or a version)
    baseline_version: str = MISSING  # the baseline artifact that compared it
    table1_inputs: List[str] = MISSING
    table2_inputs: List[str] = MISSING
    max_images: int = MISSING
    closed_loop_trials: int = MISSING
    closed_loop: List[ClosedLoopVariant] = MISSING
    policies: List[ClosedLoopVariant] = MISSING
    log_images: int = MISSING
    force: bool = MISSING


@dataclass
class UnseenConfig:
    """The unseen-size test set (``pipeline.unseen``): Tables 1 and 2 on heaps of other boxes,
    and the closed loop on heaps of them."""

    boxes: str = MISSING  # a file of conf/boxes/ (the heaps' box sizes)
    train_version: str = MISSING  # the trained network ("latest" or a version)
    baseline_version: str = MISSING  # the baseline artifact that compared it
    test_scenes: int = MISSING
    closed_loop_boxes: str = MISSING  # a file of conf/eval_boxes/ (the closed loop's boxes)
    closed_loop_trials: int = MISSING  # trials per planner on the test split (0 = none)
    log_images: int = MISSING
    force: bool = MISSING


@dataclass
class AblationVariant:
    """One closed-loop run of the ablation: a name and its evaluate-stage overrides."""

    name: str = MISSING
    overrides: List[str] = MISSING
    meaning: str = MISSING  # what the row turns off, in the report's words


@dataclass
class AblationConfig:
    """The execution ablation (``pipeline.ablation``): each variant an evaluation artifact."""

    planners: List[str] = MISSING
    trials: int = MISSING
    variants: List[AblationVariant] = MISSING
    # variant name -> the only planners it runs for (its overrides cannot change the others'
    # trials, which would repeat their all_on rows); a variant not named runs for every planner
    variant_planners: Dict[str, List[str]] = MISSING
    force: bool = MISSING


@dataclass
class ReportConfig:
    """The report stage: which artifacts to gather and how many sample images to draw."""

    generate_version: str = MISSING
    label_version: str = MISSING  # no label artifact at all: the report leaves labels out
    train_version: str = MISSING  # no train artifact at all: the report leaves Table 1 out
    baseline_version: str = MISSING  # no baseline artifact at all: the report leaves Table 2 out
    evaluate_version: str = MISSING  # no evaluate artifact at all: the report leaves Table 3 out
    # no robustness artifact at all: the report leaves the robustness section out
    robustness_version: str = MISSING
    ablation_version: str = MISSING  # no ablation artifact at all: the report leaves it out
    unseen_version: str = MISSING  # no unseen-size artifact at all: the report leaves it out
    num_sample_images: int = MISSING
    # min per stage of `make reproduce` (docs/performance.md), shown beside run_time.csv's times
    run_time_budget_min: Dict[str, float] = MISSING
    force: bool = MISSING


@dataclass
class LoggingConfig:
    """Rerun / MCAP logging. Not part of any version key: it changes logs only."""

    max_logged_scenes: int = MISSING  # per stage run; scenes beyond this are stored but not logged
    progress: bool = MISSING


@dataclass
class ExecutorConfig:
    """Where the scene-parallel stages run their shards (``pipeline.executor``), chosen with
    ``executor=local|ray``. Not part of any version key: the artifacts are the same under both.

    ``name``: ``"local"`` (a fork process pool on this machine) or ``"ray"`` (Ray actors).
    The other fields are read by ``ray`` only: ``address`` of a Ray cluster (null: start a
    private local instance for the run; on a cluster ``paths.root`` must be a filesystem shared
    by every node at the same path), CPUs reserved per worker, the private instance's object
    store size, and whether the workers' output is printed by the driver.
    """

    name: str = MISSING
    address: Optional[str] = MISSING
    num_cpus_per_task: float = MISSING
    object_store_memory_mb: int = MISSING
    log_to_driver: bool = MISSING


@dataclass
class PipelineConfig:
    """The root of every stage's configuration."""

    experiment: str = MISSING
    seed: int = MISSING
    paths: PathsConfig = field(default_factory=PathsConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    bin: BinConfig = field(default_factory=BinConfig)
    boxes: BoxesConfig = field(default_factory=BoxesConfig)
    objects: ObjectsConfig = field(default_factory=ObjectsConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    depth_filter: DepthFilterConfig = field(default_factory=DepthFilterConfig)
    generate: GenerateConfig = field(default_factory=GenerateConfig)
    hand: HandConfig = field(default_factory=HandConfig)
    robot: RobotSchema = field(default_factory=RobotSchema)
    surfaces: SurfaceConfig = field(default_factory=SurfaceConfig)
    label: LabelConfig = field(default_factory=LabelConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    suction: SuctionSchema = field(default_factory=SuctionSchema)
    dexnet: DexNetSchema = field(default_factory=DexNetSchema)
    baseline: BaselineConfig = field(default_factory=BaselineConfig)
    motion: MotionSchema = field(default_factory=MotionSchema)
    servo: ServoSchema = field(default_factory=ServoSchema)
    evaluate: EvaluateConfig = field(default_factory=EvaluateConfig)
    robustness: RobustnessConfig = field(default_factory=RobustnessConfig)
    ablation: AblationConfig = field(default_factory=AblationConfig)
    unseen: UnseenConfig = field(default_factory=UnseenConfig)
    eval_boxes: BoxesConfig = field(default_factory=BoxesConfig)
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)


def register_configs() -> None:
    """Register the schema so YAML files can extend it (``defaults: [pipeline_schema, ...]``)."""
    cs = ConfigStore.instance()
    cs.store(name="pipeline_schema", node=PipelineConfig)


register_configs()
