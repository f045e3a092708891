"""Publishing the report artifact's README.md, figures/ and tables/ into ``paths.reports``."""

from __future__ import annotations

import os
import shutil
import uuid
from pathlib import Path

PUBLISHED = ("README.md", "figures", "tables")


def publish(artifact_dir: Path, reports_dir: Path) -> list[Path]:
    """Copy README.md, figures/ and tables/ of the artifact into ``reports_dir``.

    The files are first copied into a temporary sibling folder of ``reports_dir`` (same file
    system), then moved over the old ones with ``os.replace`` (README.md last), so a reader never
    sees a half-written file. Files in ``reports_dir`` that the artifact does not hold are kept.
    """
    artifact_dir, reports_dir = Path(artifact_dir), Path(reports_dir)
    rels = []
    for name in PUBLISHED:
        src = artifact_dir / name
        if src.is_file():
            rels.append(Path(name))
        elif src.is_dir():
            rels += sorted(p.relative_to(artifact_dir) for p in src.rglob("*") if p.is_file())
    rels.sort(key=lambda p: (p == Path("README.md"), p.as_posix()))  # README.md last
    reports_dir.mkdir(parents=True, exist_ok=True)
    tmp = reports_dir.parent / f".tmp-{reports_dir.name}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        for rel in rels:
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(artifact_dir / rel, tmp / rel)
        for rel in rels:
            (reports_dir / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / rel, reports_dir / rel)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return [reports_dir / rel for rel in rels]
