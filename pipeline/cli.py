"""Shared plumbing for the stages' thin command-line wrappers."""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from typing import Callable

from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts.fingerprint import REPO_ROOT
from pipeline.config import register_configs

CONF_DIR = str(REPO_ROOT / "conf")

if not OmegaConf.has_resolver("repo_root"):
    OmegaConf.register_new_resolver("repo_root", lambda: str(REPO_ROOT))
register_configs()


def default_workers(requested: int) -> int:
    """``requested`` if positive, else the number of cores this process may use."""
    if requested > 0:
        return requested
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def data_root(cfg: DictConfig) -> Path:
    return Path(cfg.paths.data)


def stage_main(stage_fn: Callable[[DictConfig], object]) -> Callable[[DictConfig], None]:
    """Wrap a stage function for ``@hydra.main``: known errors print one clear line, exit 2."""
    from pipeline.artifacts.store import ArtifactError

    @functools.wraps(stage_fn)
    def main(cfg: DictConfig) -> None:
        try:
            stage_fn(cfg)
        except (ArtifactError, FileNotFoundError, ValueError) as e:
            print(f"error: {e}", file=sys.stderr)
            sys.exit(2)

    return main


def compose(config_name: str, overrides: list[str]) -> DictConfig:
    """The config a stage gets from ``python -m pipeline.<config_name> <overrides>``.

    For tests, benchmarks and notebooks; raises Hydra's errors on unknown keys or bad types.
    """
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(version_base="1.3", config_dir=CONF_DIR):
            return hydra_compose(config_name=config_name, overrides=overrides)
    finally:
        GlobalHydra.instance().clear()
