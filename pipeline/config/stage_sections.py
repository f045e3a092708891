"""The stages' sections of the schema: generate, label, model and train, the Dex-Net-style
baseline, evaluate, the studies (robustness, unseen, ablation) and the report. Units and frames
as in ``pipeline.config.schema``."""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from pipeline.config.physical import CameraRandomisationConfig, HeapModelSchema


@dataclass
class BaselineOODConfig:
    """The out-of-domain GQ-CNN's training heaps (``baseline.ood``; variant ``gqcnn_ood``)."""

    num_scenes: int = MISSING  # training heaps of ``objects``
    num_val_scenes: int = MISSING  # validation heaps of ``objects``
    scenes_per_shard: int = MISSING
    candidates_per_scene: int = MISSING


@dataclass
class GenerateConfig:
    """The generation stage: heaps per split, storage, parallelism."""

    num_scenes: int = MISSING  # training scenes; validation and test are given separately
    num_val_scenes: int = MISSING
    num_test_scenes: int = MISSING
    scenes_per_shard: int = MISSING
    depth_unit: float = (
        MISSING  # stored depth = round(depth_m / depth_unit) as uint16 (0 = no data)
    )
    size_jitter: float = MISSING  # each box edge scaled by U(1 - j, 1 + j) in size_jitter_splits
    size_jitter_splits: list[str] = MISSING  # splits whose boxes are jittered (others: exact sizes)
    carton_splits: list[str] = MISSING  # splits whose boxes come from boxes.cartons (when set)
    camera_randomisation: CameraRandomisationConfig = field(
        default_factory=CameraRandomisationConfig
    )
    workers: int = MISSING  # 0 = all cores; does not change the artifact
    force: bool = MISSING  # recompute even if this version exists


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
    """The training stage (``pipeline.stages.train``) and what it stores for the planner."""

    label_version: str = MISSING
    epochs: int = MISSING  # the most epochs; fewer when validation-based stopping ends it
    patience: int = MISSING  # stop after this many epochs without a lower val loss (0: never)
    batch_size: int = MISSING  # paper Sec. 6
    lr: float = MISSING  # Adam, paper Sec. 6 (the constant schedule's rate)
    schedule: ScheduleSchema = MISSING  # the rate over the run (``pipeline.planner.schedule``)
    betas: list[float] = MISSING
    alpha: float = MISSING  # focal loss, Sec. 4.1
    gamma: float = MISSING
    lambda_coord: float = MISSING
    lambda_class: float = MISSING
    depth_scale: float = MISSING  # m: input = (depth - D_ground) / depth_scale
    missing_depth_value: float = MISSING  # network input where depth = 0 (no data)
    augment_flip: str = MISSING  # "none" | "u" (horizontal) | "v" (vertical) | "uv"
    max_train_images: int = MISSING  # 0 = the whole train split
    channels_last: bool = MISSING  # train in the channels-last memory layout (faster on CPU)
    threshold: float | None = MISSING  # th of Eq. 3; None: calibrated on val (planner.calibration)
    threshold_grid: list[float] = MISSING  # th values calibration scores (conf)
    match_radius_px: float = MISSING  # Table 1: a prediction within this of a same-class truth
    ranking: RankingSchema = MISSING  # Eqs. 7-10 (``pipeline.planner.ranking.RankingConfig``)
    num_threads: int = (
        MISSING  # torch CPU threads (fixed: results depend on it); split among DDP ranks
    )
    loader_workers: int = (
        MISSING  # processes decoding batches (0 = the training process); result-neutral
    )
    device: str = MISSING  # "auto" (CUDA when available) | "cpu" | "cuda"
    log_samples: int = MISSING  # test images logged with their predictions
    force: bool = MISSING


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
    planarity: PlanaritySchema = (
        MISSING  # the analytic variant (``dexnet.quality.PlanarityConfig``)
    )
    object_margin: float = MISSING  # m: object mask = depth at least this above the bin floor


@dataclass
class BaselineConfig:
    """The comparison stage (``pipeline.stages.baseline``): GQ-CNN training and Table 2."""

    generate_version: str = MISSING
    train_version: str = MISSING  # the project's planner for Table 2; "none" leaves it out
    candidates_per_scene: int = MISSING  # sampled and labelled per training / validation scene
    max_train_scenes: int = MISSING  # 0 = the whole train split
    epochs: int = MISSING
    batch_size: int = MISSING
    lr: float = MISSING
    weight_decay: float = MISSING
    num_threads: int = MISSING
    channels_last: bool = MISSING  # the GQ-CNN's training tensors' memory layout
    variants: list[str] = MISSING
    ood: BaselineOODConfig = MISSING  # the gqcnn_ood variant's training heaps (``objects``)
    max_eval_images: int = MISSING  # 0 = the whole test split
    table2_radius_px: float = MISSING
    curve_min_px: int = MISSING
    curve_max_px: int = MISSING
    log_samples: int = MISSING
    workers: int = MISSING
    force: bool = MISSING


@dataclass
class EvaluateConfig:
    """The closed-loop evaluation stage (``pipeline.stages.evaluate``)."""

    planners: list[str] = (
        MISSING  # built-in names, or plug-ins (package.module:Class, entry points)
    )
    split: str = MISSING  # dev | test: which stream of heaps (docs/closed_loop.md, "Splits")
    # what the run-time check knows of the heap: observed (its depth image) | truth (ablation)
    collision_model: str = MISSING
    heap_model: HeapModelSchema = field(default_factory=HeapModelSchema)
    dexnet_variant: str = MISSING  # gqcnn | gqcnn_ood | planarity (a baseline variant)
    dexnet_pattern: str = MISSING  # the cup that serves Dex-Net's single suction point
    dcnn_threshold: float | None = MISSING  # th of Eq. 3 for the closed loop; None: the model's
    dcnn_fallback_ratio: float | None = MISSING  # second tier above this times th; None: off
    stop_on_box_contact: bool = MISSING  # True: touching any box but the target fails the attempt
    check_reachability: bool = MISSING  # run-time robot-level check of the planned grasp
    max_candidates_checked: int = MISSING
    # m: the check first asks this clearance from the bin on the servo's path; None: off
    preferred_bin_clearance: float | None = MISSING
    retry_policy: str = MISSING  # "skip_failed" | "repeat" (the plain protocol)
    retry_same_point_m: float = MISSING
    retry_neighbour_m: float = MISSING  # m: the heap this near the failed point is its surroundings
    retry_depth_change_m: float = MISSING  # m: a larger depth change is a change
    retry_changed_area_m2: float = MISSING  # m²: this much changed area near the point: changed
    # after these outcomes every pattern at the failed point is skipped, not only the failed one
    retry_point_outcomes: list[str] = MISSING
    retry_drop_single_cup: bool = MISSING  # after a single cup dropped a box: no single cup there
    retry_no_seal_two_cups: bool = MISSING  # after B found no seal: no B there for the trial
    face_split_m: float = MISSING  # split the home region at other planner points this far away
    check_hand_fit: bool = MISSING  # the run-time check tests the pattern's cups on the surface
    single_cup_fallback: bool = MISSING  # a rejected B is tried with L, then R
    single_cup_fallback_order: str = MISSING  # at_once: right after the B; last: after all grasps
    two_cups_first: str = MISSING  # none | second_tier | all: an L or R tried with B first
    b_quarter_turn: bool = MISSING  # a B is also tried with the hand turned by 90°
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
    overrides: list[str] = MISSING


@dataclass
class RobustnessConfig:
    """The robustness study (``pipeline.stages.robustness``)."""

    sensor: str = MISSING
    noisy_network: bool = MISSING  # also train a network on the sensor's depth (a second one)
    train_version: str = MISSING  # the network under test ("latest" or a version)
    baseline_version: str = MISSING  # the baseline artifact that compared it
    table1_inputs: list[str] = MISSING
    table2_inputs: list[str] = MISSING
    max_images: int = MISSING
    closed_loop_trials: int = MISSING
    closed_loop: list[ClosedLoopVariant] = MISSING
    policies: list[ClosedLoopVariant] = MISSING
    log_images: int = MISSING
    force: bool = MISSING


@dataclass
class UnseenConfig:
    """The unseen-size test set (``pipeline.stages.unseen``): Tables 1 and 2 on heaps of other
    boxes, and the closed loop on heaps of them."""

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
    overrides: list[str] = MISSING
    meaning: str = MISSING  # what the row turns off, in the report's words


@dataclass
class AblationConfig:
    """The execution ablation (``pipeline.stages.ablation``): one evaluation artifact a variant."""

    planners: list[str] = MISSING
    trials: int = MISSING
    variants: list[AblationVariant] = MISSING
    # variant name -> the only planners it runs for (its overrides cannot change the others'
    # trials, which would repeat their all_on rows); a variant not named runs for every planner
    variant_planners: dict[str, list[str]] = MISSING
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
    run_time_budget_min: dict[str, float] = MISSING
    force: bool = MISSING
