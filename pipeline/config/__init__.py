"""Structured (dataclass) configuration schema, registered with Hydra's ConfigStore:
``schema`` (the root, :class:`PipelineConfig`), ``physical`` (the cell and its instruments),
``stage_sections`` (each stage's settings), ``build`` (algorithm configs from sections)."""

from pipeline.config.schema import PipelineConfig, register_configs

__all__ = ["PipelineConfig", "register_configs"]
