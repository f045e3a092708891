"""Versioned, atomically written, verifiable stage artifacts.

Layout: ``<paths.data>/<stage>/<version>/`` holding ``manifest.json``, ``log.rrd``,
``log.mcap`` and the stage's files; ``<paths.data>/<stage>/latest`` is a symlink to the newest
version. See ``store.py`` for the write protocol and ``version.py`` for the key.
"""

from pipeline.artifacts.store import (  # noqa: F401
    ArtifactError,
    ArtifactWriter,
    StageRun,
    artifact_file,
    available_versions,
    check_artifact,
    load_manifest,
    resolve_artifact,
    run_stage,
    verify_artifact,
)
from pipeline.artifacts.version import compute_version, stage_config  # noqa: F401
