"""Re-hash every artifact under ``data/`` and ``models/`` against its manifest.

    python -m pipeline.tools.verify                 # all under the repository or $BINPICK_ROOT
    python -m pipeline.tools.verify --root /tmp/r1  # another paths.root

Exit status 0 when every file matches, 1 when any file is missing, changed or unlisted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pipeline.artifacts.fingerprint import REPO_ROOT
from pipeline.artifacts.store import MANIFEST, verify_artifact


def find_artifacts(root: Path) -> list[Path]:
    """Folders holding a manifest under ``root/data`` and ``root/models`` (not temporary ones)."""
    found = []
    for top in (root / "data", root / "models"):
        if not top.is_dir():
            continue
        for manifest in sorted(top.rglob(MANIFEST)):
            folder = manifest.parent
            if any(part.startswith(".") for part in folder.relative_to(top).parts):
                continue
            if folder.is_symlink() or any(
                p.is_symlink() for p in folder.parents if top in p.parents
            ):
                continue
            found.append(folder)
    return found


def verify_all(root: Path) -> dict[Path, list[str]]:
    return {folder: verify_artifact(folder) for folder in find_artifacts(root)}


def main(argv: list[str] | None = None) -> int:
    import os

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--root",
        type=Path,
        default=Path(os.environ.get("BINPICK_ROOT", REPO_ROOT)),
        help="the paths.root holding data/ and models/",
    )
    args = parser.parse_args(argv)
    results = verify_all(args.root)
    if not results:
        print(f"no artifacts under {args.root}/data or {args.root}/models")
        return 0
    bad = 0
    for folder, problems in results.items():
        rel = folder.relative_to(args.root)
        if problems:
            bad += 1
            print(f"FAIL {rel}")
            for problem in problems:
                print(f"     {problem}")
        else:
            print(f"ok   {rel}")
    print(
        f"{len(results) - bad} of {len(results)} artifacts verified"
        + (f"; {bad} failed: recompute them with <stage>.force=true" if bad else "")
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
