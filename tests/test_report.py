"""The report stage on the session's smoke pipeline (4 train, 1 val, 2 test scenes, a smoke
network; ``tests/conftest.py``), copied into a root of its own."""

from __future__ import annotations

import csv
import io
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import smoke_overrides
from matplotlib import image as mpimg

from pipeline.artifacts import ArtifactError, load_manifest, verify_artifact
from pipeline.dataset.labels import LabelSet
from pipeline.dataset.scenes import SPLITS, SceneDataset
from pipeline.grasping.types import GraspClass
from pipeline.planner.evaluate import PAPER_TABLE1
from pipeline.report import report
from pipeline.report.dataset import dataset_stats
from pipeline.report.figures import outline
from pipeline.report.labels import LABEL_NOT_RUN, LabelInfo, check_labels
from pipeline.report.publish import publish
from pipeline.report.robustness import ROBUSTNESS_NOT_RUN
from pipeline.report.training import TABLE1_SECTION, TRAIN_NOT_RUN
from pipeline.runtime.cli import compose, stage_main
from pipeline.stages.generate import generate
from pipeline.stages.label import label
from pipeline.stages.train import train

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
LABEL_TABLES = ("label_classes.csv", "label_ng_reasons.csv", "surface_accuracy.csv")


def _cfg(root: Path, name: str, *overrides: str):
    """The smoke config of stage ``name`` rooted in ``root``, with the session pipeline's scene
    counts (conftest's ``smoke_overrides``)."""
    return compose(name, smoke_overrides(root, *overrides))


def _generate_and_label(root: Path) -> None:
    """The session pipeline's generation, labels and smoke training (1 epoch, width 0.0625, on
    CPU, where it is deterministic), built again in ``root``."""
    generate(_cfg(root, "generate"))
    label(_cfg(root, "label"))
    train(_cfg(root, "train"))


@pytest.fixture(scope="module")
def root_a(smoke_pipeline, tmp_path_factory) -> Path:
    """A copy of the session's smoke pipeline (the report writes into its root)."""
    return smoke_pipeline.copy(tmp_path_factory.mktemp("root_a")).root


@pytest.fixture(scope="module")
def report_a(root_a: Path) -> Path:
    return report(_cfg(root_a, "report"))


def _read_csv(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(path.read_text())))


def _section(readme: str, heading: str) -> str:
    """The README text under ``heading`` (a whole line) up to the next heading of any level."""
    lines = readme.splitlines()
    start = lines.index(heading) + 1
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("#")), len(lines))
    return "\n".join(lines[start:end])


def _md_table(text: str) -> list[dict[str, str]]:
    """The first Markdown table in ``text`` as one dict per row (cells stripped)."""
    rows = []
    for line in text.splitlines():
        if line.startswith("|"):
            rows.append(line)
        elif rows:  # the first table has ended
            break
    cells = [[c.strip() for c in row.strip().strip("|").split("|")] for row in rows]
    return [dict(zip(cells[0], r)) for r in cells[2:]]


@pytest.fixture(scope="module")
def label_dir(root_a: Path) -> Path:
    return (root_a / "data" / "label" / "latest").resolve()


@pytest.fixture(scope="module")
def label_metrics(label_dir: Path) -> dict:
    return load_manifest(label_dir)["metrics"]


@pytest.fixture(scope="module")
def root_gen_only(root_a: Path, tmp_path_factory) -> Path:
    """A root holding root_a's generation artifact and no label artifact."""
    root = tmp_path_factory.mktemp("gen_only")
    shutil.copytree(root_a / "data" / "generate", root / "data" / "generate", symlinks=True)
    return root


def test_readme_names_versions_and_split_counts(root_a: Path, report_a: Path) -> None:
    gen_dir = (root_a / "data" / "generate" / "latest").resolve()
    readme = (root_a / "reports" / "README.md").read_text()
    assert gen_dir.name in readme
    assert report_a.name in readme
    label_dir = (root_a / "data" / "label" / "latest").resolve()
    assert label_dir.name in readme
    train_dir = (root_a / "models" / "train" / "latest").resolve()
    assert load_manifest(report_a)["upstream"] == {
        "generate": gen_dir.name,
        "label": label_dir.name,
        "train": train_dir.name,
    }
    dataset = _section(readme, "## Dataset")
    rows = {
        line.split("|")[1].strip(): [c.strip() for c in line.strip("|\n ").split("|")]
        for line in dataset.splitlines()
        if line.startswith("| ") and line.split("|")[1].strip() in (*SPLITS, "all")
    }
    assert [rows[s][1] for s in SPLITS] == ["4", "1", "2"]
    assert rows["all"][1] == "7"
    for split in SPLITS:
        ds = SceneDataset(gen_dir, split)
        assert int(rows[split][2]) == sum(len(scene.boxes) for scene in ds)
    assert "## Paper tables" in readme and "Table" in readme
    # nothing run-dependent: no absolute paths, no creation times
    assert str(root_a) not in readme
    assert load_manifest(gen_dir)["created"] not in readme
    assert load_manifest(label_dir)["created"] not in readme


def test_readme_label_tables_match_label_manifest(
    root_a: Path, report_a: Path, label_metrics: dict
) -> None:
    readme = (root_a / "reports" / "README.md").read_text()
    assert "## Labels (paper Sec. 4.3, Figs. 4–6)" in readme
    assert LABEL_NOT_RUN not in readme
    splits = label_metrics["splits"]

    classes = _md_table(_section(readme, "### Grasp points per class"))
    assert [(r["split"], r["level"]) for r in classes] == [
        (s, level) for s in (*SPLITS, "all") for level in ("hand", "robot")
    ]
    for r in classes:
        key = "hand_level_classes" if r["level"] == "hand" else "classes"
        if r["split"] == "all":
            counts = {c.name: sum(splits[s][key][c.name] for s in SPLITS) for c in GraspClass}
            scenes = sum(splits[s]["scenes"] for s in SPLITS)
        else:
            counts, scenes = splits[r["split"]][key], splits[r["split"]]["scenes"]
        total = sum(counts.values())
        assert int(r["scenes"]) == scenes
        assert int(r["grasp points"]) == total
        if r["split"] != "all":
            assert total == splits[r["split"]]["grasp_points"]
        for c in GraspClass:
            assert int(r[c.name]) == counts[c.name]
            assert r[f"{c.name} (%)"] == f"{100 * counts[c.name] / total:.1f}"

    reasons = {r["NG reason"]: r for r in _md_table(_section(readme, "### NG reasons"))}
    assert {"too_small", "center_occluded", "ik", "joint_limits", "collision", "total"} <= set(
        reasons
    )
    for name, r in reasons.items():
        for s in SPLITS:
            expected = (
                splits[s]["classes"]["NG"]
                if name == "total"
                else splits[s]["ng_reasons"].get(name, 0)
            )
            assert int(r[s]) == expected, (name, s)
    assert int(reasons["total"]["all"]) == sum(splits[s]["classes"]["NG"] for s in SPLITS)
    assert reasons["too_small"]["level"] == "hand"
    assert reasons["collision"]["level"] == "robot"

    accuracy = {
        r["split"]: r for r in _md_table(_section(readme, "### Surface detection accuracy"))
    }
    assert list(accuracy) == [*SPLITS, "all"]
    columns = {
        "images": "images",
        "found": "found",
        "missed": "missed",
        "spurious": "spurious",
        "precision": "precision",
        "recall": "recall",
        "centre error median (px)": "center_err_px_median",
        "centre error p90 (px)": "center_err_px_p90",
        "centre error median (mm)": "center_err_mm_median",
        "centre error p90 (mm)": "center_err_mm_p90",
        "normal error median (deg)": "normal_err_deg_median",
        "normal error p90 (deg)": "normal_err_deg_p90",
    }
    for split, r in accuracy.items():
        m = (
            label_metrics["surface_accuracy"]
            if split == "all"
            else splits[split]["surface_accuracy"]
        )
        for header, key in columns.items():
            if m[key] is None:
                assert r[header] == "—"
            elif isinstance(m[key], int):
                assert int(r[header]) == m[key], (split, header)
            else:
                assert r[header] == f"{m[key]:.3f}", (split, header)

    # Throughput is run-dependent: the README points at the label manifest instead of copying it.
    throughput = _section(readme, "### Throughput")
    assert "timings" in throughput and "scenes_per_s" in throughput
    label_version = load_manifest(report_a)["upstream"]["label"]
    assert not re.search(r"\d", throughput.replace(label_version, "")), throughput


def test_label_csvs_agree_with_manifest_and_labels(
    root_a: Path, report_a: Path, label_dir: Path, label_metrics: dict
) -> None:
    tables = root_a / "reports" / "tables"
    splits = label_metrics["splits"]
    classes = {(r["split"], r["level"]): r for r in _read_csv(tables / "label_classes.csv")}
    for s in SPLITS:
        labels = LabelSet(label_dir, s)
        final = np.zeros(4, int)
        hand = np.zeros(4, int)
        for i in range(len(labels)):
            final += np.bincount(labels[i]["grasp_class"], minlength=4)
            hand += np.bincount(labels[i]["hand_class"], minlength=4)
        for level, counts, key in (
            ("robot", final, "classes"),
            ("hand", hand, "hand_level_classes"),
        ):
            row = classes[(s, level)]
            for c in GraspClass:
                assert int(row[c.name]) == counts[c] == splits[s][key][c.name]
                assert float(row[f"{c.name} (%)"]) == pytest.approx(
                    100 * counts[c] / counts.sum(), abs=0.005
                )
    for level in ("hand", "robot"):
        assert int(classes[("all", level)]["grasp points"]) == sum(
            splits[s]["grasp_points"] for s in SPLITS
        )

    reasons = {r["NG reason"]: r for r in _read_csv(tables / "label_ng_reasons.csv")}
    for s in SPLITS:
        for name, n in splits[s]["ng_reasons"].items():
            assert int(reasons[name][s]) == n
        assert int(reasons["total"][s]) == splits[s]["classes"]["NG"]

    accuracy = {r["split"]: r for r in _read_csv(tables / "surface_accuracy.csv")}
    for split, r in accuracy.items():
        m = (
            label_metrics["surface_accuracy"]
            if split == "all"
            else splits[split]["surface_accuracy"]
        )
        assert int(r["found"]) == m["found"] and int(r["missed"]) == m["missed"]
        assert int(r["spurious"]) == m["spurious"] and int(r["images"]) == m["images"]
        for header, key in (
            ("recall", "recall"),
            ("precision", "precision"),
            ("centre error median (px)", "center_err_px_median"),
            ("centre error p90 (mm)", "center_err_mm_p90"),
            ("normal error p90 (deg)", "normal_err_deg_p90"),
        ):
            if m[key] is None:
                assert r[header] == ""
            else:
                assert float(r[header]) == m[key]  # full precision in the CSV
    assert sum(int(accuracy[s]["images"]) for s in SPLITS) == 7
    for name in LABEL_TABLES:
        assert (report_a / "tables" / name).read_bytes() == (tables / name).read_bytes()


def test_label_consistency_check(root_a: Path, label_dir: Path, label_metrics: dict) -> None:
    gen_dir = (root_a / "data" / "generate" / "latest").resolve()
    stats = dataset_stats(gen_dir)
    manifest = load_manifest(label_dir)
    good = LabelInfo(
        label_dir, manifest, manifest["metrics"]["splits"], manifest["metrics"]["surface_accuracy"]
    )
    check_labels(good, stats)
    bad_splits = load_manifest(label_dir)["metrics"]["splits"]
    bad_splits["test"]["classes"]["NG"] += 1
    with pytest.raises(ArtifactError, match="inconsistent"):
        check_labels(LabelInfo(label_dir, manifest, bad_splits, {}), stats)


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
            # the table rounds to 0.1 px: the same rounding of the dataset's own mean
            assert float(r[area_col]) == round(pixels[r["box type"]] / n, 1)
    # the artifact's copies are the published ones
    for name in ("dataset_splits.csv", "box_types.csv"):
        assert (report_a / "tables" / name).read_bytes() == (tables / name).read_bytes()


def test_figures_are_png(root_a: Path, report_a: Path) -> None:
    for name in ("sample_depth.png", "boxes_per_scene.png", "labels_sample.png", "pr_curve.png"):
        path = root_a / "reports" / "figures" / name
        data = path.read_bytes()
        assert data[:8] == PNG_SIGNATURE
        assert b"Software" not in data  # the matplotlib version tag is left out
        img = mpimg.imread(path)
        assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100


def test_artifact_is_complete_and_logged(report_a: Path) -> None:
    assert verify_artifact(report_a) == []
    files = load_manifest(report_a)["files"]
    assert {
        "README.md",
        "log.rrd",
        "log.mcap",
        "tables/dataset_splits.csv",
        "tables/box_types.csv",
        "figures/sample_depth.png",
        "figures/boxes_per_scene.png",
        "figures/labels_sample.png",
        *(f"tables/{name}" for name in LABEL_TABLES),
    } <= set(files)
    from pipeline.tracking import mcap_message_counts

    counts = mcap_message_counts(report_a / "log.mcap")
    assert counts["/report/tables/dataset_splits"] >= 1
    assert counts["/report/tables/box_types"] >= 1
    assert counts["/report/figures"] >= 1
    for name in LABEL_TABLES:
        assert counts[f"/report/tables/{Path(name).stem}"] >= 1


@pytest.mark.slow
def test_report_is_reproducible_across_roots(root_a: Path, report_a: Path, tmp_path: Path) -> None:
    """The whole chain built again in another root gives a byte-identical report."""
    root_b = tmp_path / "root_b"
    _generate_and_label(root_b)
    report_b = report(_cfg(root_b, "report"))
    assert report_b.name == report_a.name
    assert load_manifest(report_b)["upstream"] == load_manifest(report_a)["upstream"]
    files_a = load_manifest(report_a)["files"]
    files_b = load_manifest(report_b)["files"]
    files_a.pop("log.rrd")
    files_b.pop("log.rrd")
    # measured wall-clock time, skipped as `make repro-check` skips it (metrics.volatile_files)
    volatile = load_manifest(report_a)["metrics"]["volatile_files"]
    assert volatile == load_manifest(report_b)["metrics"]["volatile_files"]
    assert "tables/run_time.csv" in volatile
    for rel in volatile:
        files_a.pop(rel)
        files_b.pop(rel)
    assert "log.mcap" in files_a and "figures/labels_sample.png" in files_a
    assert {"tables/table1_precision.csv", "figures/pr_curve.png"} <= set(files_a)
    assert files_a == files_b
    for rel in files_a:  # byte-identical, not just equal hashes in the manifests
        assert (report_a / rel).read_bytes() == (report_b / rel).read_bytes(), rel


def test_report_without_label_artifact(root_gen_only: Path, report_a: Path) -> None:
    out = report(_cfg(root_gen_only, "report"))
    gen_version = (root_gen_only / "data" / "generate" / "latest").resolve().name
    assert load_manifest(out)["upstream"] == {"generate": gen_version}
    assert out.name != report_a.name
    readme = (out / "README.md").read_text()
    assert LABEL_NOT_RUN in readme
    assert "Labelling: not run yet (`make label`)" in readme
    assert "Training: not run yet (`make train`)" in readme and TRAIN_NOT_RUN in readme
    assert ROBUSTNESS_NOT_RUN in readme and "## Robustness" in readme
    assert "### Grasp points per class" not in readme
    files = load_manifest(out)["files"]
    assert "tables/dataset_splits.csv" in files and "figures/sample_depth.png" in files
    assert not any(
        name in rel
        for rel in files
        for name in (*LABEL_TABLES, "labels_sample", "table1_precision", "pr_curve")
    )
    # the dataset part is the same as with labels
    for rel in ("tables/dataset_splits.csv", "tables/box_types.csv", "figures/sample_depth.png"):
        assert (out / rel).read_bytes() == (report_a / rel).read_bytes()


def test_named_label_version_must_exist(root_gen_only: Path) -> None:
    with pytest.raises(ArtifactError, match="label"):
        report(_cfg(root_gen_only, "report", "report.label_version=0123456789abcdef"))


def test_label_artifact_of_another_generation_is_an_error(root_a: Path, tmp_path: Path) -> None:
    gen_dir = (root_a / "data" / "generate" / "latest").resolve()
    root = tmp_path / "mismatch"
    # A second generation artifact (a copy under another name) and root_a's label artifact,
    # which was made from the first one.
    shutil.copytree(gen_dir, root / "data" / "generate" / "0000000000000000")
    shutil.copytree(root_a / "data" / "label", root / "data" / "label", symlinks=True)
    with pytest.raises(ArtifactError, match="make label") as info:
        report(_cfg(root, "report", "report.generate_version=0000000000000000"))
    assert gen_dir.name in str(info.value) and "report.label_version" in str(info.value)


def test_rerun_reuses_artifact(root_a: Path, report_a: Path) -> None:
    manifest = (report_a / "manifest.json").read_text()
    assert report(_cfg(root_a, "report")) == report_a
    assert (report_a / "manifest.json").read_text() == manifest


def test_publish_keeps_other_files(report_a: Path, tmp_path: Path) -> None:
    reports = tmp_path / "reports"
    (reports / "tables").mkdir(parents=True)
    (reports / "tables" / "table2_dexnet.csv").write_text("from another stage\n")
    (reports / "README.md").write_text("old\n")
    publish(report_a, reports)
    assert (reports / "tables" / "table2_dexnet.csv").read_text() == "from another stage\n"
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
    np.testing.assert_array_equal(outline(mask), expected)


def test_sample_count_is_validated(root_a: Path) -> None:
    with pytest.raises(ValueError, match="num_sample_images"):
        report(_cfg(root_a, "report", "report.num_sample_images=-1"))


COLUMNS = {"Top 1": "top1", "Top 1 %": "top1pct", "Top 5 %": "top5pct", "Top 10 %": "top10pct"}


def test_table1_matches_train_manifest(root_a: Path, report_a: Path) -> None:
    train_dir = (root_a / "models" / "train" / "latest").resolve()
    manifest = load_manifest(train_dir)
    ours = manifest["metrics"]["table1"]
    readme = (root_a / "reports" / "README.md").read_text()
    assert train_dir.name in readme and TRAIN_NOT_RUN not in readme
    section = _section(readme, f"## {TABLE1_SECTION}")
    rows = {r[""]: r for r in _md_table(section)}
    th = manifest["metrics"]["threshold"]["value"]
    pooled = f"this reproduction, pooled top k % (th = {th:g})"
    per_image = f"this reproduction, per-image top k % (th = {th:g})"
    old = "old definition (no threshold; top 1 over images with a prediction)"
    assert list(rows) == ["paper", pooled, per_image, old]
    assert ours["threshold"] == th
    assert [rows["paper"][h] for h in COLUMNS] == ["83.10 %", "80.25 %", "67.22 %", "55.64 %"]

    def pct(v):
        return "—" if v is None else f"{100 * v:.2f} %"

    for header, key in COLUMNS.items():
        assert rows[pooled][header] == pct(ours[key]), header
        assert rows[old][header] == pct(ours["legacy"][key]), header
        assert rows[per_image][header] == pct(
            ours["top1"] if key == "top1" else ours["per_image"][key]
        ), header
    # the calibration curve that chose th is shown, with th among its rows
    curve = _md_table(section[section.index("**Threshold th = ") :])
    assert [float(r["th"]) for r in curve] == [
        r["threshold"] for r in manifest["metrics"]["threshold"]["curve"]
    ]
    assert th in [float(r["th"]) for r in curve]
    # the definition and the network are described right there, without timings
    assert "same class" in section and "NG" in section and "ceil(k/100" in section
    assert f"{ours['radius_px']:g} pixels" in section
    net = manifest["metrics"]["network"]
    assert f"{net['parameters']:,} parameters" in section
    assert f"{net['macs_per_image']:,} multiply-accumulates" in section
    flip = manifest["config"]["train"]["augment_flip"]
    assert (
        f"{manifest['metrics']['images']['train']} training images (each mirrored at random: "
        f"`train.augment_flip={flip}`) for 1 epoch"
    ) in section
    curve_csv = (root_a / "reports" / "tables" / "training_curve.csv").read_text().splitlines()
    assert curve_csv[0] == "epoch,train loss,val loss,"
    assert len(curve_csv) == 1 + len(manifest["metrics"]["train_loss_per_epoch"])
    assert curve_csv[1].endswith(",model")  # one epoch: it is the model
    assert "images_per_s" not in section and "train_s" not in section
    paper_tables = _section(readme, "## Paper tables")
    assert "Table 1" in paper_tables and "reported above" in paper_tables

    table = {r[""]: r for r in _read_csv(root_a / "reports" / "tables" / "table1_precision.csv")}
    for header, key in COLUMNS.items():
        assert float(table["paper"][header]) == pytest.approx(100 * PAPER_TABLE1[key], abs=1e-4)
        if ours[key] is None:
            assert table[pooled][header] == ""
        else:
            assert float(table[pooled][header]) == pytest.approx(100 * ours[key], abs=1e-4)
    assert (report_a / "figures" / "pr_curve.png").read_bytes()[:8] == PNG_SIGNATURE
    assert "train_version" not in load_manifest(report_a)["config"]["report"]


def test_train_artifact_of_another_label_is_an_error(root_a: Path, tmp_path: Path) -> None:
    # root_a's train artifact with only its generation artifact: no label artifact to match.
    root = tmp_path / "train_mismatch"
    shutil.copytree(root_a / "data" / "generate", root / "data" / "generate", symlinks=True)
    shutil.copytree(root_a / "models" / "train", root / "models" / "train", symlinks=True)
    with pytest.raises(ArtifactError, match="make train") as info:
        report(_cfg(root, "report"))
    assert "report.train_version" in str(info.value)
