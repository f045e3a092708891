"""Structured (dataclass) configuration schema, registered with Hydra's ConfigStore."""

from pipeline.config.schema import (  # noqa: F401
    BinConfig,
    BoxesConfig,
    BoxType,
    CameraConfig,
    DepthFilterConfig,
    ExecutorConfig,
    GenerateConfig,
    LoggingConfig,
    PathsConfig,
    PhysicsConfig,
    PipelineConfig,
    ReportConfig,
    SensorConfig,
    register_configs,
)
