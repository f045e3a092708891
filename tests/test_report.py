"""The report stage on a tiny generated dataset (4 train, 1 val, 2 test scenes)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest
from matplotlib import image as mpimg

from pipeline.artifacts import ArtifactError, load_manifest, verify_artifact
from pipeline.cli import compose, stage_main
from pipeline.dataset.scenes import SPLITS, SceneDataset
from pipeline.generate import generate
from pipeline.report import _outline, publish, report

TINY = ("generate.num_scenes=4", "generate.num_val_scenes=1", "generate.num_test_scenes=2",
        "generate.workers=1")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _cfg(root: Path, name: str, *overrides: str):
    # Same overrides as conftest's smoke_cfg, for module-scoped fixtures (tmp_path is per test).
    return compose(name, ["experiment=smoke", f"paths.root={root}", "logging.progress=false",
                          *overrides])


@pytest.fixture(scope="module")
def root_a(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("root_a")
    generate(_cfg(root, "generate", *TINY))
    return root


@pytest.fixture(scope="module")
def report_a(root_a: Path) -> Path:
    return report(_cfg(root_a, "report"))


def _read_csv(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(path.read_text())))


def test_readme_names_versions_and_split_counts(root_a: Path, report_a: Path) -> None:
    gen_dir = (root_a / "data" / "generate" / "latest").resolve()
    readme = (root_a / "reports" / "README.md").read_text()
    assert gen_dir.name in readme
    assert report_a.name in readme
    assert load_manifest(report_a)["upstream"] == {"generate": gen_dir.name}
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|\n ").split("|")]
            for line in readme.splitlines()
            if line.startswith("| ") and line.split("|")[1].strip() in (*SPLITS, "all")}
    assert [rows[s][1] for s in SPLITS] == ["4", "1", "2"]
    assert rows["all"][1] == "7"
    for split in SPLITS:
        ds = SceneDataset(gen_dir, split)
        assert int(rows[split][2]) == sum(len(scene.boxes) for scene in ds)
    assert "## Paper tables" in readme and "Table" in readme
    # nothing run-dependent: no absolute paths, no creation times
    assert str(root_a) not in readme
    assert load_manifest(gen_dir)["created"] not in readme


def test_csv_tables_agree_with_dataset(root_a: Path, report_a: Path) -> None:
    gen_dir = (root_a / "data" / "generate" / "latest").resolve()
    tables = root_a / "reports" / "tables"
    splits = {r["split"]: r for r in _read_csv(tables / "dataset_splits.csv")}
    assert [int(splits[s]["scenes"]) for s in SPLITS] == [4, 1, 2]
    per_split_boxes = {s: sum(len(sc.boxes) for sc in SceneDataset(gen_dir, s)) for s in SPLITS}
    for s in SPLITS:
        assert int(splits[s]["boxes"]) == per_split_boxes[s]
    assert int(splits["all"]["boxes"]) == sum(per_split_boxes.values())
    steps_col = next(k for k in splits["train"] if k.startswith("median settle steps"))
    assert "(1/240 s)" in steps_col
    train_steps = [sc.settle_steps for sc in SceneDataset(gen_dir, "train")]
    assert float(splits["train"][steps_col]) == pytest.approx(np.median(train_steps))

    types = _read_csv(tables / "box_types.csv")
    counts: dict[str, int] = {}
    pixels: dict[str, int] = {}
    for s in SPLITS:
        for sc in SceneDataset(gen_dir, s):
            px = np.bincount(sc.mask.ravel(), minlength=len(sc.boxes) + 1)
            for box in sc.boxes:
                counts[box.type_name] = counts.get(box.type_name, 0) + 1
                pixels[box.type_name] = pixels.get(box.type_name, 0) + int(px[box.instance])
    assert sum(int(r["boxes"]) for r in types) == sum(per_split_boxes.values())
    area_col = next(k for k in types[0] if k.startswith("mean visible area"))
    for r in types:
        n = counts.get(r["box type"], 0)
        assert int(r["boxes"]) == n
        if n:
            assert float(r[area_col]) == pytest.approx(pixels[r["box type"]] / n, abs=0.05)
    # the artifact's copies are the published ones
    for name in ("dataset_splits.csv", "box_types.csv"):
        assert (report_a / "tables" / name).read_bytes() == (tables / name).read_bytes()


def test_figures_are_png(root_a: Path, report_a: Path) -> None:
    for name in ("sample_depth.png", "boxes_per_scene.png"):
        path = root_a / "reports" / "figures" / name
        data = path.read_bytes()
        assert data[:8] == PNG_SIGNATURE
        assert b"Software" not in data  # the matplotlib version tag is left out
        img = mpimg.imread(path)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100


def test_artifact_is_complete_and_logged(report_a: Path) -> None:
    assert verify_artifact(report_a) == []
    files = load_manifest(report_a)["files"]
    assert {"README.md", "log.rrd", "log.mcap", "tables/dataset_splits.csv",
            "tables/box_types.csv", "figures/sample_depth.png",
            "figures/boxes_per_scene.png"} <= set(files)
    from pipeline.tracking import mcap_message_counts

    counts = mcap_message_counts(report_a / "log.mcap")
    assert counts["/report/tables/dataset_splits"] >= 1
    assert counts["/report/tables/box_types"] >= 1
    assert counts["/report/figures"] >= 1


def test_report_is_reproducible_across_roots(root_a: Path, report_a: Path, tmp_path: Path) -> None:
    root_b = tmp_path / "root_b"
    generate(_cfg(root_b, "generate", *TINY))
    report_b = report(_cfg(root_b, "report"))
    assert report_b.name == report_a.name
    files_a = load_manifest(report_a)["files"]
    files_b = load_manifest(report_b)["files"]
    files_a.pop("log.rrd")
    files_b.pop("log.rrd")
    assert "log.mcap" in files_a
    assert files_a == files_b


def test_rerun_reuses_artifact(root_a: Path, report_a: Path) -> None:
    manifest = (report_a / "manifest.json").read_text()
    assert report(_cfg(root_a, "report")) == report_a
    assert (report_a / "manifest.json").read_text() == manifest


def test_publish_keeps_other_files(report_a: Path, tmp_path: Path) -> None:
    reports = tmp_path / "reports"
    (reports / "tables").mkdir(parents=True)
    (reports / "tables" / "table1_precision.csv").write_text("from another stage\n")
    (reports / "README.md").write_text("old\n")
    publish(report_a, reports)
    assert (reports / "tables" / "table1_precision.csv").read_text() == "from another stage\n"
    assert (reports / "README.md").read_bytes() == (report_a / "README.md").read_bytes()
    assert (reports / "figures" / "sample_depth.png").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["reports"]  # no temporary folder left


def test_missing_generation_artifact_is_a_clear_error(smoke_cfg, capsys) -> None:
    cfg = smoke_cfg("report")
    with pytest.raises(ArtifactError, match="make generate"):
        report(cfg)
    with pytest.raises(SystemExit) as exit_info:
        stage_main(report)(cfg)
    assert exit_info.value.code == 2
    assert "make generate" in capsys.readouterr().err


def test_outline_marks_box_pixels_next_to_other_values() -> None:
    mask = np.zeros((5, 5), dtype=np.uint8)
    mask[1:4, 1:4] = 1  # a 3x3 box: its 8 border pixels are outline, the centre is not
    expected = mask.astype(bool).copy()
    expected[2, 2] = False
    np.testing.assert_array_equal(_outline(mask), expected)


def test_sample_count_is_validated(root_a: Path) -> None:
    with pytest.raises(ValueError, match="num_sample_images"):
        report(_cfg(root_a, "report", "report.num_sample_images=-1"))

