"""Typed configuration schema for every stage.

Every stage composes the same :class:`PipelineConfig`; each stage hashes only the sections it
reads (see ``pipeline.artifacts.version``) so that, for example, changing ``report.*`` does not
change the generation artifact's version.

Values live in ``conf/``: one YAML file per physical set-up (camera, bin, box set, physics,
sensor) and one per experiment scale (``experiment/smoke|default|paper``). The dataclass
defaults here exist only so that the schema is complete; the YAML files are the source of truth.

Units: metres, kilograms, seconds, pixels. Frames: world (z up, origin at the centre of the bin
floor's top surface), camera (OpenCV: x right, y down, z forward along the optical axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING


@dataclass
class PathsConfig:
    """Where artifacts go. ``root`` holds ``data/``, ``models/`` and ``reports/``."""

    root: str = MISSING  # set in conf/paths/default.yaml to the repository root
    data: str = "${paths.root}/data"
    models: str = "${paths.root}/models"
    reports: str = "${paths.root}/reports"


@dataclass
class CameraConfig:
    """Pinhole depth camera (SR300-like), OpenCV convention.

    ``fx, fy, cx, cy`` are in pixels for a ``width`` × ``height`` image; pixel (u, v) = (0, 0)
    is the centre of the top-left pixel. ``height_above_bin_floor`` is the distance from the
    optical centre to the bin floor's top surface, along the (vertical) optical axis.
    """

    name: str = "sr300"
    width: int = 416
    height: int = 416
    fx: float = 411.7
    fy: float = 411.7
    cx: float = 207.5
    cy: float = 207.5
    height_above_bin_floor: float = 0.625
    near: float = 0.1
    far: float = 2.0
    renderer: str = "raycast"  # "raycast" | "tinyrenderer" (pipeline.camera.render)


@dataclass
class BinConfig:
    """An open box (tote) standing on the ground, centred on the world origin."""

    inner_length_x: float = 0.40
    inner_width_y: float = 0.30
    wall_height: float = 0.15
    wall_thickness: float = 0.010
    floor_thickness: float = 0.020
    lateral_friction: float = 0.5


@dataclass
class BoxType:
    """A cuboid of edge lengths ``size`` = (x, y, z) in metres."""

    name: str = MISSING
    size: List[float] = MISSING


@dataclass
class BoxesConfig:
    """The box set that heaps are drawn from (uniformly over ``types``)."""

    name: str = "paper"
    types: List[BoxType] = field(default_factory=list)
    density: float = 400.0  # kg/m^3
    lateral_friction: float = 0.5
    min_count: int = 0
    max_count: int = 20


@dataclass
class PhysicsConfig:
    """pybullet settings and the rest criterion (see docs/simulation.md)."""

    time_step: float = 1.0 / 240.0
    solver_iterations: int = 50
    gravity: float = -9.81
    drop_height_above_bin_floor: float = 0.625
    drop_interval_steps: int = 20  # "trickle": one box every N steps
    drop_margin: float = 0.03  # keep drop xy this far inside the bin walls
    friction_anchor: bool = True  # Bullet friction anchors on every box and bin part
    rest_check_interval_steps: int = 10
    rest_window_steps: int = 60  # at rest: over this many steps ...
    rest_corner_displacement: float = 0.0005  # m: ... no box corner moved farther than this
    max_settle_steps: int = 3000


@dataclass
class SensorConfig:
    """Depth-sensor model applied after rendering (``enabled: false`` = ideal depth).

    See ``pipeline.camera.sensor`` for the model and ``conf/sensor/sr300.yaml`` for the
    parameters' sources. Metres and degrees.
    """

    name: str = "ideal"
    enabled: bool = False
    noise_sigma_0: float = 0.0  # m, σ(z, θ) = σ0 + σ2·z² + σθ/√z · θ²/(π/2 − θ)²
    noise_sigma_2: float = 0.0  # m per m²
    noise_sigma_theta: float = 0.0  # m·√m
    projector_baseline: float = 0.0  # m along the camera's x axis (0 = no projector shadow)
    dropout_angle_start_deg: float = 90.0  # steep-surface dropout starts at this incidence angle
    dropout_angle_deg: float = 90.0  # ... and is certain from this one (90 = off)
    min_range: float = 0.0  # m: no data nearer than this
    max_range: float = 100.0  # m: no data beyond this
    edge_jump: float = 0.01  # m: a depth step between 4-neighbours
    edge_dropout_prob: float = 0.0  # chance a pixel at a depth step is lost
    quantisation_step: float = 0.0  # m (0 = none)


@dataclass
class DepthFilterConfig:
    """Depth preprocessing before the planners (``pipeline.camera.depth_filter``); 0 = off."""

    name: str = "none"
    fill_holes_px: int = 0  # fill holes from the farthest neighbour, this many 3 x 3 passes
    median_px: int = 0  # median kernel (3 or 5) after filling


@dataclass
class GenerateConfig:
    """The generation stage: heaps per split, storage, parallelism."""

    num_scenes: int = MISSING  # training scenes; validation and test are given separately
    num_val_scenes: int = MISSING
    num_test_scenes: int = MISSING
    scenes_per_shard: int = 50
    depth_unit: float = 1.0e-4  # stored depth = round(depth_m / depth_unit) as uint16 (0 = no data)
    workers: int = 0  # 0 = all cores; does not change the artifact
    force: bool = False  # recompute even if this version exists


@dataclass
class HandConfig:
    """The two-cup suction hand (paper Fig. 1b) and the hand-level fit criteria, metres."""

    cup_diameter: float = 0.018
    cup_offset: float = 0.035  # cup centre to camera centre along the hand's Y
    standoff: float = 0.15  # d*: camera to surface along the normal at the target pose
    margin: float = 0.002  # a cup disc grown by this must lie inside the visible surface
    min_area_ratio: float = 1.2  # surface area >= ratio × the active cups' area
    tie_tolerance: float = 0.001  # L/R camera heights closer than this: a tie (→ L)
    # hand rotations about the normal tried by the robot-level checks, in order (0 = paper)
    rotations_deg: List[float] = field(default_factory=lambda: [0.0])


@dataclass
class SurfaceConfig:
    """Surface detection by RANSAC plane fits on per-object point clusters."""

    distance_threshold: float = 0.002  # RANSAC inlier distance, m
    ransac_backend: str = "numpy"  # "numpy" (seeded, deterministic) or "open3d" (segment_plane)
    ransac_n: int = 3
    num_iterations: int = 200
    min_inliers: int = 150  # fewer points: not a surface
    max_surfaces_per_object: int = 3
    truth_min_visible_px: int = 150  # ground-truth faces with fewer visible pixels are ignored
    match_max_center_dist: float = 0.02  # m, detected ↔ true face matching
    match_max_normal_deg: float = 20.0


@dataclass
class RobotSchema:
    """The 7-DoF robot (``pipeline.robot.RobotConfig`` documents each field)."""

    base_position: List[float] = field(default_factory=lambda: [-0.42, 0.0, 0.10])
    base_yaw_deg: float = 0.0
    pedestal_half_size_xy: float = 0.08
    home_camera_height: float = 0.625
    ik_max_iterations: int = 100
    ik_residual_threshold: float = 1e-6
    ik_joint_damping: float = 1e-3
    ik_hand_damping: float = 0.1
    ik_refinements: int = 4
    ik_restarts: int = 8
    ik_restart_noise_rad: float = 1.0
    position_tolerance: float = 0.002
    orientation_tolerance_deg: float = 1.0
    collision_margin: float = 0.005
    self_collision_margin: float = 0.0
    path_check: bool = True  # check the approach path, not only the grasp pose
    path_step_m: float = 0.01
    path_step_deg: float = 2.0
    path_bin_clearance: float = 0.0


@dataclass
class LabelConfig:
    """The labelling stage."""

    generate_version: str = "latest"
    robot_checks: bool = True  # robot-level labels (IK, joint limits, collisions)
    workers: int = 0  # 0 = all cores; does not change the artifact
    force: bool = False


@dataclass
class ModelConfig:
    """The grasp-point DCNN (``pipeline.planner.network.NetworkConfig`` documents each field)."""

    name: str = "darknet23"
    width: float = 1.0  # channel multiplier on Darknet-19 widths (1.0 = the paper's network)
    grid: int = 13  # N
    input_size: int = 416
    num_classes: int = 4
    leaky_slope: float = 0.1


@dataclass
class TrainConfig:
    """The training stage (``pipeline.train``) and what it stores for the planner."""

    label_version: str = "latest"
    epochs: int = MISSING  # the most epochs; fewer when validation-based stopping ends it
    patience: int = 0  # stop after this many epochs without a lower val loss (0: never)
    batch_size: int = 16  # paper Sec. 6
    lr: float = 1.0e-4  # Adam, paper Sec. 6
    betas: List[float] = field(default_factory=lambda: [0.9, 0.999])
    alpha: float = 0.25  # focal loss, Sec. 4.1
    gamma: float = 2.0
    lambda_coord: float = 1.0
    lambda_class: float = 1.0
    depth_scale: float = 0.1  # m: input = (depth - D_ground) / depth_scale
    missing_depth_value: float = 0.5  # network input where depth = 0 (no data)
    augment_flip: str = "none"  # "none" | "u" (horizontal) | "v" (vertical) | "uv"
    max_train_images: int = 0  # 0 = the whole train split
    channels_last: bool = False  # train in the channels-last memory layout (faster on CPU)
    threshold: Optional[float] = None  # th of Eq. 3; None: calibrated on val (planner.calibration)
    threshold_grid: List[float] = field(default_factory=list)  # th values calibration scores (conf)
    match_radius_px: float = 16.0  # Table 1: a prediction within this of a same-class truth
    num_threads: int = 2  # torch CPU threads (fixed: results depend on it); split among DDP ranks
    loader_workers: int = 1  # processes decoding batches (0 = the training process); result-neutral
    device: str = "auto"  # "auto" (CUDA when available) | "cpu" | "cuda"
    log_samples: int = 4  # test images logged with their predictions
    force: bool = False


@dataclass
class SuctionSchema:
    """The suction contact model (``pipeline.dexnet.contact.SuctionModelConfig`` documents each
    field). The cup radius comes from ``hand.cup_diameter``; box density from ``boxes.density``."""

    vacuum_force: float = 12.7  # N per cup
    friction: float = 0.5
    compliance: float = 0.003  # m
    ring_points: int = 16
    visibility_tolerance: float = 0.003  # m
    perturbations: int = 16
    sigma_position: float = 0.002  # m
    sigma_axis_deg: float = 5.0
    quality_threshold: float = 0.5


@dataclass
class DexNetSchema:
    """The Dex-Net-style planner: sampler, cross-entropy method, GQ-CNN, analytic quality."""

    border_px: int = 68
    max_approach_angle_deg: float = 30.0
    max_tries: int = 10000
    sobel_ksize: int = 3
    num_seed_samples: int = 200
    num_gmm_samples: int = 50
    num_iters: int = 3
    gmm_refit_p: float = 0.25
    gmm_component_frac: float = 0.4
    gmm_reg_covar: float = 0.01
    max_resamples: int = 100
    crop_window_px: int = 64  # crop of the depth image around a candidate, pixels
    crop_size: int = 32  # the crop resized to this (GQ-CNN input), pixels
    crop_depth_scale: float = 0.05  # m: crop input = (depth - candidate depth) / scale
    crop_missing_value: float = 1.0  # crop input where depth = 0 (no data)
    pose_depth_scale: float = 0.1  # m: pose input = (candidate depth - D_ground) / scale
    width: int = 16  # channels of the first conv layer (doubled per block)
    fc: int = 128
    planarity_sigma: float = 0.001  # m
    planarity_min_coverage: float = 0.8
    object_margin: float = 0.005  # m: object mask = depth at least this above the bin floor


@dataclass
class BaselineConfig:
    """The comparison stage (``pipeline.baseline``): GQ-CNN training and Table 2."""

    generate_version: str = "latest"
    train_version: str = "latest"  # the project's planner for Table 2; "none" leaves it out
    candidates_per_scene: int = 32  # sampled and labelled per training / validation scene
    max_train_scenes: int = 0  # 0 = the whole train split
    epochs: int = MISSING
    batch_size: int = 64
    lr: float = 1.0e-3
    weight_decay: float = 1.0e-4
    num_threads: int = 2
    variants: List[str] = field(default_factory=lambda: ["gqcnn", "planarity"])
    max_eval_images: int = 0  # 0 = the whole test split
    table2_radius_px: float = 30.0
    curve_min_px: int = 5
    curve_max_px: int = 50
    log_samples: int = 8
    workers: int = 0
    force: bool = False


@dataclass
class MotionSchema:
    """Robot speed limits and the timing of the pick sequence (``conf/motion/``)."""

    max_joint_speed: float = 3.14  # rad/s per joint (xArm6: 180 deg/s)
    max_joint_accel: float = 10.0  # rad/s^2, for the point-to-point move times
    servo_max_linear_speed: float = 0.5  # m/s, camera, during visual servoing
    servo_max_angular_speed: float = 1.5  # rad/s
    approach_speed: float = 0.05  # m/s along the camera axis, from d* to contact
    press_depth: float = 0.003  # m, cups pressed this far past the surface
    lift_height: float = 0.10  # m, straight up with the box
    lift_speed: float = 0.25  # m/s
    suction_on_s: float = 0.10  # vacuum build-up before lifting
    suction_off_s: float = 0.10  # release at the conveyor
    place_position: List[float] = field(default_factory=lambda: [-0.05, 0.40, 0.30])  # m, world: camera above the conveyor
    pregrasp_standoff: float = 0.30  # m, the pre-grasp's largest distance along the normal
    pregrasp_wall_margin: float = 0.01  # m, camera and cup lips this far inside the walls
    pregrasp_image_fraction: float = 0.7  # lift: the centre within this share of the half-FOV
    approach: str = "lift"  # "lift" | "pregrasp" | "direct" (the paper: straight to d*)


@dataclass
class ServoSchema:
    """Surface feature descriptor (Eqs. 11-14) and 2.5D visual servoing (Eqs. 15-28)."""

    window: int = 21
    window_tolerance_depth: float = 0.0  # m; > 0: window RANSAC tolerance ε1·min(1, Z/this)
    seed_repair: bool = True  # crack and small-component repairs of the seed
    track_normal_deg: float = 20.0  # servo: stay on the surface of the previous frame's normal
    eps_distance: float = 0.004
    eps_normal: float = 0.05
    min_pixels: int = 50
    gain: float = 0.4  # lambda
    gain_per_step: bool = True
    control_rate_hz: float = 30.0
    tolerance_xy: float = 0.01
    tolerance_log_z: float = 0.01
    tolerance_rot_deg: float = 1.0
    timeout_s: float = 8.0
    joint_damping: float = 0.001
    normal_smoothing: int = 0  # descriptor: average n_p over (2k+1)^2 pixels (noisy depth)


@dataclass
class EvaluateConfig:
    """The closed-loop evaluation stage (``pipeline.evaluate``)."""

    planners: List[str] = field(default_factory=lambda: ["dcnn", "dexnet", "oracle"])
    dexnet_variant: str = "gqcnn"  # gqcnn | planarity
    dexnet_pattern: str = "L"  # the cup that serves Dex-Net's single suction point
    dcnn_threshold: Optional[float] = None  # th of Eq. 3 for the closed loop; None: the model's
    stop_on_box_contact: bool = False  # True: touching any box but the target fails the attempt
    check_reachability: bool = True  # run-time robot-level check of the planned grasp
    max_candidates_checked: int = 50
    retry_policy: str = "skip_failed"  # "skip_failed" | "repeat" (the plain protocol)
    retry_same_point_m: float = 0.03
    retry_moved_m: float = 0.005
    retry_moved_deg: float = 5.0
    ranking_policy: str = "paper"  # "paper" (Eq. 7) | "height_tiebreak" (Sec. 8.4's proposed fix)
    inclination_tie_deg: float = 10.0  # height_tiebreak: inclinations closer than this tie
    min_area_ratio: float = 0.0  # 0: off (paper); 1.2: Sec. 8.4's surface-area safety check
    train_version: str = "latest"
    baseline_version: str = "latest"
    num_trials: int = MISSING
    boxes_per_trial: int = 12
    max_failures_per_target: int = 5
    max_attempts_per_trial: int = 40
    num_threads: int = 1
    log_trials: int = 2
    workers: int = 0
    force: bool = False


@dataclass
class ClosedLoopVariant:
    """One closed-loop run of the robustness study: a network and evaluate-stage overrides."""

    name: str = MISSING
    model: str = "clean"  # clean | noisy: the network trained on ideal / on the sensor's depth
    overrides: List[str] = field(default_factory=list)


@dataclass
class RobustnessConfig:
    """The robustness study (``pipeline.robustness``)."""

    sensor: str = "sr300"
    table1_inputs: List[str] = field(default_factory=lambda: ["ideal", "sensor"])
    table2_inputs: List[str] = field(default_factory=lambda: ["ideal", "sensor"])
    max_images: int = 0
    closed_loop_trials: int = 10
    closed_loop: List[ClosedLoopVariant] = field(default_factory=list)
    policies: List[ClosedLoopVariant] = field(default_factory=list)
    log_images: int = 4
    force: bool = False


@dataclass
class UnseenConfig:
    """The unseen-size test set (``pipeline.unseen``): Tables 1 and 2 on heaps of other boxes."""

    boxes: str = "unseen"  # a file of conf/boxes/ (the heaps' box sizes)
    test_scenes: int = 300
    log_images: int = 4
    force: bool = False


@dataclass
class AblationVariant:
    """One closed-loop run of the ablation: a name and its evaluate-stage overrides."""

    name: str = MISSING
    overrides: List[str] = field(default_factory=list)


@dataclass
class AblationConfig:
    """The execution ablation (``pipeline.ablation``): each variant an evaluation artifact."""

    planners: List[str] = field(default_factory=lambda: ["oracle", "dcnn"])
    trials: int = 10
    variants: List[AblationVariant] = field(default_factory=list)
    force: bool = False


@dataclass
class ReportConfig:
    """The report stage: which artifacts to gather and how many sample images to draw."""

    generate_version: str = "latest"
    label_version: str = "latest"  # no label artifact at all: the report leaves labels out
    train_version: str = "latest"  # no train artifact at all: the report leaves Table 1 out
    baseline_version: str = "latest"  # no baseline artifact at all: the report leaves Table 2 out
    evaluate_version: str = "latest"  # no evaluate artifact at all: the report leaves Table 3 out
    # no robustness artifact at all: the report leaves the robustness section out
    robustness_version: str = "latest"
    ablation_version: str = "latest"  # no ablation artifact at all: the report leaves it out
    unseen_version: str = "latest"  # no unseen-size artifact at all: the report leaves it out
    num_sample_images: int = 6
    force: bool = False


@dataclass
class LoggingConfig:
    """Rerun / MCAP logging. Not part of any version key: it changes logs only."""

    max_logged_scenes: int = 100  # per stage run; scenes beyond this are stored but not logged
    progress: bool = True


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

    name: str = "local"
    address: Optional[str] = None
    num_cpus_per_task: float = 1.0
    object_store_memory_mb: int = 512
    log_to_driver: bool = True


@dataclass
class PipelineConfig:
    """The root of every stage's configuration."""

    experiment: str = MISSING
    seed: int = 0
    paths: PathsConfig = field(default_factory=PathsConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    bin: BinConfig = field(default_factory=BinConfig)
    boxes: BoxesConfig = field(default_factory=BoxesConfig)
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
