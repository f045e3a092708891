"""The artifacts a study stage (robustness, unseen) compares: the trained network and its baseline.

A study stage reads the trained network and the baseline artifact that compared it
(``compared_pair``: ``latest`` by default, as ``make reproduce`` leaves them), then runs the
other stages it needs by name (``pipeline.runtime.cli.run_named_stage``) with the command's own
overrides plus its own; each run is reused when its version already exists (``run_stage``), so
a study after ``make reproduce`` recomputes only what differs.
"""

from __future__ import annotations

from pathlib import Path


def compared_pair(
    data: Path, models: Path, train_version: str, baseline_version: str, prefix: str
) -> dict[str, Path]:
    """``{"train": models/train/<v>, "baseline": data/baseline/<v>}``, both verified.

    ``prefix``: the study's config section, named in the errors (``<prefix>.train_version``).
    Raises ``ArtifactError`` when either is missing and ``ValueError`` when the baseline artifact
    compared another network (its Table 2 would not be this network's)."""
    from pipeline.artifacts.store import load_manifest, resolve_artifact

    dirs = {
        "train": resolve_artifact(
            models, "train", str(train_version), verify=True, key=f"{prefix}.train_version"
        ),
        "baseline": resolve_artifact(
            data, "baseline", str(baseline_version), verify=True, key=f"{prefix}.baseline_version"
        ),
    }
    compared = (load_manifest(dirs["baseline"]).get("upstream") or {}).get("train")
    if compared != dirs["train"].name:
        raise ValueError(
            f"baseline artifact {dirs['baseline'].name} compared train artifact {compared}, not "
            f"{dirs['train'].name}: its Dex-Net-style rows would not sit beside this network's. "
            f"Rerun `make baseline` (baseline.train_version={dirs['train'].name}), or pass "
            f"matching {prefix}.train_version and {prefix}.baseline_version"
        )
    return dirs
