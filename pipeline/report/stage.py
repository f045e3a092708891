"""The report stage itself: resolve every section's upstream artifact, compute the version, and
build the artifact by looping over the sections (tables, figures, README, logs, metrics).

See the package docstring (``pipeline.report``) for the artifact's files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from pipeline.artifacts import compute_version, run_stage, stage_config
from pipeline.artifacts.store import StageRun
from pipeline.report.ablation import AblationSection
from pipeline.report.baseline import BaselineSection
from pipeline.report.closed_loop import ClosedLoopSection
from pipeline.report.dataset import DatasetSection
from pipeline.report.labels import LabelsSection
from pipeline.report.publish import publish
from pipeline.report.readme import render_readme
from pipeline.report.robustness import RobustnessSection
from pipeline.report.run_time import RUN_TIME_FILE, run_time_table
from pipeline.report.section import Context, Section
from pipeline.report.tables import Table
from pipeline.report.training import TrainingSection
from pipeline.report.unseen import UnseenSection
from pipeline.runtime.cli import stage_command
from pipeline.tracking import StageLog

STAGE = "report"
SECTIONS = ("report",)  # the config sections of the version key (``stage_config``)
# The upstream versions cover which artifacts are read.
NOT_AFFECTING_RESULT = (
    "report.force",
    "report.generate_version",
    "report.label_version",
    "report.train_version",
    "report.baseline_version",
    "report.evaluate_version",
    "report.robustness_version",
    "report.ablation_version",
    "report.unseen_version",
)
# Files whose content is measured wall-clock time: the same artifacts give other numbers on
# another run, so `make repro-check` skips them (they are listed in metrics.volatile_files).
VOLATILE_FILES = ("tables/planning_time.csv", "tables/table3_timing.csv", RUN_TIME_FILE)

DATASET = DatasetSection()  # the generation artifact: the one section that is not optional
LABELS = LabelsSection()
TRAINING = TrainingSection()
BASELINE = BaselineSection()
CLOSED_LOOP = ClosedLoopSection()
ROBUSTNESS = RobustnessSection()
ABLATION = AblationSection()
UNSEEN = UnseenSection()
# The sections in the order they are resolved (each after the artifacts it must match), which
# is also the order of the README's "Artifacts used" table.
REPORT_SECTIONS: tuple[Section, ...] = (
    DATASET,
    LABELS,
    TRAINING,
    BASELINE,
    CLOSED_LOOP,
    ROBUSTNESS,
    ABLATION,
    UNSEEN,
)
# The order their tables and figures are made in: that of the logs and the README's figures.
BUILD_ORDER: tuple[Section, ...] = (
    DATASET,
    LABELS,
    TRAINING,
    BASELINE,
    CLOSED_LOOP,
    ABLATION,
    UNSEEN,
    ROBUSTNESS,
)
# The order of their Markdown in the README.
README_ORDER: tuple[Section, ...] = (
    DATASET,
    LABELS,
    TRAINING,
    BASELINE,
    UNSEEN,
    CLOSED_LOOP,
    ABLATION,
    ROBUSTNESS,
)


def report(cfg: DictConfig) -> Path:
    """Run the report stage; returns the artifact folder (reused if it already exists).

    Raises ``ArtifactError`` when there is no generation artifact, and when an optional upstream
    artifact exists but does not match (e.g. a label artifact of another generation artifact;
    no label artifact at all is fine: the report then leaves the labels out).
    """
    ctx = Context(cfg)
    for section in REPORT_SECTIONS:
        ctx.found[section.name] = section.resolve(ctx)
    found = [(s, ctx.found[s.name]) for s in REPORT_SECTIONS if ctx.found[s.name] is not None]
    extra: dict[str, Any] = {}
    for section, info in found:
        extra.update(section.configure(info, ctx))
    config = stage_config(cfg, SECTIONS, NOT_AFFECTING_RESULT)
    config.update(extra)
    upstream = {section.name: info.version for section, info in found}
    version = compute_version(STAGE, config, upstream)

    def body(run: StageRun) -> None:
        built = [(s, ctx.found[s.name]) for s in BUILD_ORDER if ctx.found[s.name] is not None]
        tables: dict[str, Table] = {}
        for section, info in built:
            tables.update((t.name, t) for t in section.tables(info, ctx))
        run_time = run_time_table(
            (ctx.root, ctx.models), upstream, dict(cfg.report.run_time_budget_min)
        )
        tables[run_time.name] = run_time
        for t in tables.values():
            path = run.work_dir / "tables" / f"{t.name}.csv"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(t.csv_text())

        figures: dict[str, str] = {}  # relative path: caption
        for section, info in built:
            figures.update(section.figures(info, ctx, run.work_dir))

        readme = render_readme(
            run.version,
            [(s, ctx.found[s.name]) for s in REPORT_SECTIONS],
            [(s, ctx.found[s.name]) for s in README_ORDER],
            tables,
            figures,
        )
        (run.work_dir / "README.md").write_text(readme)

        with StageLog(run.work_dir, app_id=f"binpick-{STAGE}", recording_id=run.version) as log:
            step = 0
            for t in tables.values():
                if f"tables/{t.name}.csv" in VOLATILE_FILES:
                    continue  # wall-clock figures: they would make the logs differ between runs
                log.set_time(sequences={"step": step}, clock_ns=step)
                log.log_text(f"report/tables/{t.name}", f"tables/{t.name}.csv\n{t.csv_text()}")
                step += 1
            log.set_time(sequences={"step": step}, clock_ns=step)
            log.log_text("report/figures", "figures: " + ", ".join(figures))
            step += 1
            log.set_time(sequences={"step": step}, clock_ns=step)
            log.log_text("report/readme", readme)

        for section in REPORT_SECTIONS:
            run.metrics.update(section.metrics(ctx.found[section.name]))
        run.metrics.update(
            {
                "volatile_files": sorted(f for f in VOLATILE_FILES if (run.work_dir / f).is_file()),
                "tables": sorted(f"tables/{name}.csv" for name in tables),
                "figures": sorted(figures),
            }
        )

    out = run_stage(ctx.root, STAGE, version, config, upstream, body, force=bool(cfg.report.force))
    published = publish(out, Path(cfg.paths.reports))
    print(f"[{STAGE}] published {len(published)} files to {cfg.paths.reports}")
    return out


main = stage_command("report", report)
