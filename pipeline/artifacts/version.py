"""The version key of a stage artifact.

``version = sha256(stage, stage config, upstream versions, source hash, package versions)``,
truncated to 16 hex digits. The stage config is the resolved config restricted to the sections
the stage reads, minus keys that cannot change its result (paths, logging, worker counts,
``force``). Two runs with equal keys produce identical artifact files.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from typing import Any

from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts.fingerprint import package_versions, source_hash

VERSION_LENGTH = 16


def stage_config(
    cfg: DictConfig, sections: Iterable[str], ignore: Iterable[str] = ()
) -> dict[str, Any]:
    """The resolved sub-config that determines a stage's result, as plain containers.

    Args:
        cfg: the full composed config.
        sections: top-level keys the stage reads (e.g. ``["seed", "camera", "generate"]``).
        ignore: dotted keys inside those sections that do not change the result
            (e.g. ``"generate.workers"``).
    """
    out: dict[str, Any] = {}
    for section in sections:
        node = OmegaConf.select(cfg, section, throw_on_missing=True)
        if isinstance(node, DictConfig):
            out[section] = OmegaConf.to_container(node, resolve=True)
        else:
            out[section] = node
    for dotted in ignore:
        parent = out
        *head, leaf = dotted.split(".")
        for key in head:
            parent = parent.get(key, {})
        if isinstance(parent, dict):
            parent.pop(leaf, None)
    return out


def compute_version(
    stage: str, config: Mapping[str, Any], upstream: Mapping[str, str], code_of: str | None = None
) -> str:
    """Hex key naming the artifact a stage would produce from these inputs.

    The source hash is that of module ``pipeline.<code_of or stage>``'s import closure.
    """
    payload = {
        "stage": stage,
        "config": config,
        "upstream": dict(sorted(upstream.items())),
        "source": source_hash(code_of or stage),
        "packages": package_versions(),
    }
    blob = json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()[:VERSION_LENGTH]
