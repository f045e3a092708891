"""The upstream artifacts the report reads, and the one resolver of an optional upstream.

Every section but the dataset's reports an artifact it can do without (labels, training, ...):
``resolve_upstream`` finds it from ``report.<stage>_version``, or returns None when that is
"latest" and the stage has not run yet; a named version that does not exist is an error. The
artifact's files must match its manifest, its manifest's ``upstream`` must name the versions the
report reads (``Match``), and the section's ``load`` checks that its manifest holds what the
section reports.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from pipeline.artifacts import (
    ArtifactError,
    available_versions,
    check_artifact,
    load_manifest,
    resolve_artifact,
)


@dataclass
class ArtifactInfo:
    """An upstream artifact the report reads: its folder and its manifest."""

    folder: Path
    manifest: dict

    @property
    def version(self) -> str:
        return self.folder.name

    @property
    def metrics(self) -> dict:
        return self.manifest["metrics"]

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> ArtifactInfo:
        """The info of a resolved artifact; subclasses raise ``ArtifactError`` here when the
        manifest lacks what their section reports."""
        return cls(folder, manifest)


Info = TypeVar("Info", bound=ArtifactInfo)


def lacks_metrics(folder: Path, stage: str, what: str) -> ArtifactError:
    """The error for a ``stage`` artifact in ``folder`` whose manifest lacks ``what`` (e.g.
    ``metrics.table3``): it names the command that recomputes it."""
    return ArtifactError(
        f"{folder.name}/manifest.json ({stage}) lacks {what}; "
        f"recompute it with `make {stage}` ({stage}.force=true)."
    )


@dataclass(frozen=True)
class Match:
    """The artifact must have been made from the version the report reads of another upstream:
    its manifest's ``upstream[key]`` must equal ``expected``, or, with ``stage_dir`` (the folder
    of that upstream stage's versions), name a version that holds the same data
    (``pipeline.artifacts.equivalence.same_data``: a version made by other code whose files
    are identical but for the logs)."""

    key: str  # e.g. "generate"
    expected: str | None  # the report's version of that upstream (None: the report has none)
    message: Callable[[str, str | None], str]  # (artifact's version, its upstream[key]) -> error
    if_both_known: bool = False  # True: no check when either version is None
    stage_dir: Path | None = None  # e.g. data/generate: accept an identical version

    def check(self, version: str, upstream: dict) -> None:
        from pipeline.artifacts.equivalence import same_data

        theirs = upstream.get(self.key)
        if self.if_both_known and (theirs is None or self.expected is None):
            return
        if theirs == self.expected:
            return
        if (
            self.stage_dir is not None
            and theirs is not None
            and self.expected is not None
            and same_data(self.stage_dir, theirs, self.expected)
        ):
            return
        raise ArtifactError(self.message(version, theirs))


def resolve_upstream(
    where: Path,
    stage: str,
    version: str,
    load: Callable[[Path, dict], Info],
    matches: Iterable[Match] = (),
) -> Info | None:
    """The ``stage`` artifact under ``where`` (a data or models folder) that the report reads.

    ``version``: the config's ``report.<stage>_version``. Returns None when it is "latest" and no
    ``stage`` artifact exists yet. Raises ``ArtifactError`` when a named version does not exist,
    when the artifact's files do not match its manifest, when a ``Match`` fails, or from
    ``load`` (the section's reading of the manifest).
    """
    key = f"report.{stage}_version"
    try:
        folder = resolve_artifact(where, stage, version, key=key)
    except ArtifactError:
        if version == "latest" and not available_versions(where, stage):
            return None
        raise
    folder = check_artifact(folder, key)  # files match the manifest
    manifest = load_manifest(folder)
    upstream = manifest.get("upstream") or {}
    for match in matches:
        match.check(folder.name, upstream)
    return load(folder, manifest)
