"""A stage's artifacts as its config names them: the upstream artifacts its ``<stage>.*_version``
keys ask for, and its own artifact, keyed by its config and upstream, under ``paths.data`` with
the config's seed and ``force``.

Plumbing like the rest of ``pipeline.runtime``: it only reads the config and calls
``pipeline.artifacts``; the numbers are the stage's ``body``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts.store import StageRun, resolve_artifact, run_stage
from pipeline.artifacts.version import compute_version
from pipeline.runtime.cli import data_root


def upstream_artifact(cfg: DictConfig, stage: str, key: str, root: Path | None = None) -> Path:
    """The verified folder of the ``stage`` artifact that config key ``key`` names
    (``"label.generate_version"``: a version key or ``"latest"``), under ``root`` (default
    ``paths.data``).

    Raises:
        ArtifactError: no such complete artifact, or a file that does not match its manifest
            (the message names ``key`` and the fix).
        omegaconf.errors.MissingMandatoryValue: ``key`` is not set.
    """
    version = OmegaConf.select(cfg, key, throw_on_missing=True)
    where = data_root(cfg) if root is None else root
    return resolve_artifact(where, stage, version, verify=True, key=key)


def run_stage_from_config(
    cfg: DictConfig,
    stage: str,
    config: Mapping[str, Any],
    upstream: Mapping[str, str],
    body: Callable[[StageRun], None],
    *,
    resumable: bool = False,
) -> Path:
    """Produce (or reuse) the ``stage`` artifact of this ``config`` (the stage's sections,
    ``stage_config``) and ``upstream`` (stage or input name → version): its version from both
    (``compute_version``), then ``pipeline.artifacts.store.run_stage`` under ``paths.data``
    with the seed ``cfg.seed`` and ``<stage>.force``. The artifact folder."""
    version = compute_version(stage, config, upstream)
    seed, force = int(cfg.seed), bool(cfg[stage].force)
    return run_stage(
        data_root(cfg),
        stage,
        version,
        config,
        upstream,
        body,
        seed=seed,
        force=force,
        resumable=resumable,
    )
