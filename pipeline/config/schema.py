"""Typed configuration schema for every stage.

Every stage composes the same :class:`PipelineConfig`; each stage hashes only the sections it
reads (see ``pipeline.artifacts.version``) so that, for example, changing ``report.*`` does not
change the generation artifact's version.

The sections are declared in ``physical.py`` (the cell and its instruments) and
``stage_sections.py`` (each stage's settings); this module composes them.

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

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

from pipeline.config.physical import (
    BinConfig,
    BoxesConfig,
    CameraConfig,
    DepthFilterConfig,
    HandConfig,
    MotionSchema,
    ObjectsConfig,
    PhysicsConfig,
    RobotSchema,
    SensorConfig,
    ServoSchema,
    SuctionSchema,
    SurfaceConfig,
)
from pipeline.config.stage_sections import (
    AblationConfig,
    BaselineConfig,
    DexNetSchema,
    EvaluateConfig,
    GenerateConfig,
    LabelConfig,
    ModelConfig,
    ReportConfig,
    RobustnessConfig,
    TrainConfig,
    UnseenConfig,
)


@dataclass
class PathsConfig:
    """Where artifacts go. ``root`` holds ``data/``, ``models/`` and ``reports/``."""

    root: str = MISSING  # set in conf/paths/default.yaml to the repository root
    data: str = MISSING
    models: str = MISSING
    reports: str = MISSING


@dataclass
class LoggingConfig:
    """Rerun / MCAP logging. Not part of any version key: it changes logs only."""

    max_logged_scenes: int = MISSING  # per stage run; scenes beyond this are stored but not logged
    progress: bool = MISSING


@dataclass
class ExecutorConfig:
    """Where the scene-parallel stages run their shards (``pipeline.runtime.executor``), chosen with
    ``executor=local|ray``. Not part of any version key: the artifacts are the same under both.

    ``name``: ``"local"`` (a fork process pool on this machine) or ``"ray"`` (Ray actors).
    The other fields are read by ``ray`` only: ``address`` of a Ray cluster (null: start a
    private local instance for the run; on a cluster ``paths.root`` must be a filesystem shared
    by every node at the same path), CPUs reserved per worker, the private instance's object
    store size, and whether the workers' output is printed by the driver.
    """

    name: str = MISSING
    address: str | None = MISSING
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
