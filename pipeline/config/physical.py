"""The physical set-up's sections of the schema: camera, bin, boxes and objects, physics, sensor
and depth filters, the hand, the robot and its motion, the suction cup, the servo, the heap
model. Units and frames as in ``pipeline.config.schema``."""

from __future__ import annotations

from dataclasses import dataclass

from omegaconf import MISSING


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
    size: list[float] = MISSING


@dataclass
class CartonsConfig:
    """A continuous distribution of cartons (``pipeline.simulation.cartons``): edges from ranges,
    density from a range, mass capped at the hand's payload, held-out sizes carved out. Metres,
    kg/m³, kg."""

    long_edge: list[float] = MISSING  # [low, high] of the longest edge, m
    middle_ratio: list[float] = MISSING  # [low, high] of middle / long
    short_ratio: list[float] = MISSING  # [low, high] of short / middle
    min_edge: float = MISSING  # m: a thinner carton is drawn again
    density: list[float] = MISSING  # [low, high], kg/m³
    max_mass: float = MISSING  # kg (the hand's payload)
    held_out: list[list[float]] = MISSING  # sizes (m) kept outside the distribution ...
    held_out_margin: float = MISSING  # ... with every sorted edge within this fraction of theirs


@dataclass
class BoxesConfig:
    """The box set that heaps are drawn from (uniformly over ``types``; with ``cartons``, the
    splits of ``generate.carton_splits`` draw every box from that distribution instead)."""

    name: str = MISSING
    types: list[BoxType] = MISSING
    cartons: CartonsConfig | None = MISSING  # None: every box from types
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
    families: list[str] = MISSING  # cylinder | prism | hull, each equally likely
    cylinder_radius: list[float] = MISSING
    cylinder_length: list[float] = MISSING
    cylinder_sections: int = MISSING
    prism_sides: list[int] = MISSING
    prism_radius: list[float] = MISSING
    prism_length: list[float] = MISSING
    prism_regular_share: float = MISSING
    prism_jitter: float = MISSING
    prism_squeeze: list[float] = MISSING
    hull_semi_axis: list[float] = MISSING
    hull_points: list[int] = MISSING
    density: float = MISSING  # kg/m^3
    lateral_friction: float = MISSING
    min_count: int = MISSING  # objects per heap, uniform, inclusive
    max_count: int = MISSING
    solver_iterations: int = MISSING  # pybullet's per step while an object heap settles


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
    splits: list[str] = MISSING
    ideal_fraction: float = MISSING
    noise_sigma_0: list[float] = MISSING
    noise_sigma_2: list[float] = MISSING
    noise_sigma_theta: list[float] = MISSING
    projector_baseline: list[float] = MISSING
    dropout_angle_start_deg: list[float] = MISSING
    dropout_angle_span_deg: list[float] = MISSING  # dropout_angle_deg = start + this
    edge_dropout_prob: list[float] = MISSING
    quantisation_step: list[float] = MISSING
    hole_rate: list[float] = MISSING
    hole_size_px: list[int] = MISSING
    depth_bias: list[float] = MISSING
    depth_scale_error: list[float] = MISSING
    min_range: float = MISSING  # m, fixed (as SensorConfig's)
    max_range: float = MISSING  # m, fixed
    edge_jump: float = MISSING  # m, fixed


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
    rotations_deg: list[float] = MISSING
    # labels: a pattern whose cups would not hold the box's weight (the suction hold test) is NG
    hold_check: bool = MISSING
    # labels' hold check: the cups must also hold when they land this far off their points (m)
    hold_landing_tolerance: float = MISSING
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

    base_position: list[float] = MISSING
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
class SuctionSchema:
    """The suction contact model (``pipeline.grasping.suction.SuctionModelConfig`` documents each
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
    place_position: list[float] = MISSING  # m, world: camera above the conveyor
    pregrasp_standoff: float = MISSING  # m, the pre-grasp's largest distance along the normal
    pregrasp_wall_margin: float = MISSING  # m, camera and cup lips this far inside the walls
    pregrasp_image_fraction: float = MISSING  # lift: the centre within this share of the half-FOV
    approach: str = MISSING  # "lift" | "pregrasp" | "direct" (the paper: straight to d*)
    via_tolerance_scale: float = (
        MISSING  # the first goal counts as reached within this x servo tolerances
    )


@dataclass
class ServoSchema:
    """Surface feature descriptor (Eqs. 11-14) and 2.5D visual servoing (Eqs. 15-28)."""

    window: int = MISSING
    window_tolerance_depth: float = MISSING  # m; > 0: window RANSAC tolerance ε1·min(1, Z/this)
    seed_repair: bool = MISSING  # crack and small-component repairs of the seed
    track_normal_deg: float = MISSING  # servo: stay on the surface of the previous frame's normal
    track_offset_m: float | None = MISSING  # servo: ... and within this of its plane (m)
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
    flying_tolerance_m: float = (
        MISSING  # neighbours within this depth agree (0: no flying-pixel step)
    )
    flying_min_neighbours: int = MISSING  # a pixel needs this many agreeing neighbours of its 8
    surface_tolerance_m: float = MISSING  # the grasped face: points this near its plane (0: off)
