"""Robustness section (Secs. 8.4, 8.5): sensor noise and the paper's failure cases, from the
robustness artifact (``data/robustness/<version>``, ``report.robustness_version``; optional;
``pipeline.stages.robustness``), read from its ``robustness.json``.

Tables ``robustness_sensor_model``, ``robustness_table1`` / ``robustness_table2`` (Tables 1 and
2 per network and input), ``robustness_closed_loop`` (the closed-loop variants, each on its split:
success rate and boxes picked with their 95 % intervals, failures, trial ends, why no attempt),
``robustness_policies`` (Sec. 8.4's policies against the paper's) and ``robustness_failures``.
Figure ``robustness_depth.png``: the ideal, sensor-model and filtered depth of the first test
image of the study's noisy generation artifact (its ``artifacts.generate_noisy``), when that
artifact is under ``data/generate/``; the figure's filter (``conf/depth_filter/fill_median.yaml``)
and whether the generation artifact was found are part of the report's version key
(``config.robustness_figure``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts import ArtifactError, check_artifact
from pipeline.report.baseline import TABLE2_SECTION
from pipeline.report.figures import figure_sensor_depth
from pipeline.report.section import Context, Section
from pipeline.report.tables import (
    Column,
    Table,
    count_column,
    integer,
    number,
    table_of,
    text_column,
    times,
    trial_columns,
    within_key,
)
from pipeline.report.training import TABLE1_COLUMNS, TABLE1_SECTION
from pipeline.report.upstream import ArtifactInfo, resolve_upstream
from pipeline.runtime.cli import CONF_DIR

ROBUSTNESS_SECTION = "Robustness: sensor noise and the failure cases (Secs. 8.4, 8.5)"
ROBUSTNESS_NOT_RUN = (
    "Robustness study: not run yet (`make robustness`, i.e. "
    "`python -m pipeline.stages.robustness`)."
)
ROBUSTNESS_KEYS = ("table1", "table2", "closed_loop", "sensor", "artifacts")
ROBUSTNESS_FIGURE = "figures/robustness_depth.png"
ROBUSTNESS_FIGURE_FILTER = "fill_median"  # conf/depth_filter/<name>.yaml, the figure's 3rd panel
MODEL_LABELS = {"clean": "network under test", "noisy": "sensor-trained"}
ROBUSTNESS_PLANNERS = {
    "dcnn_clean": "ours (DCNN), network under test",
    "dcnn_noisy": "ours (DCNN), sensor-trained",
    "gqcnn": "Dex-Net-style GQ-CNN + CEM",
    "planarity": "Dex-Net-style planarity + CEM",
}
REFERENCE_POLICY = "paper"  # the policy rows are compared with this variant
SENSOR_MEANING = {  # pipeline.camera.sensor's parameters (SensorConfig); metres and degrees
    "name": "the sensor model (`conf/sensor/<name>.yaml`)",
    "enabled": "whether the model is applied (false: ideal depth)",
    "noise_sigma_0": "σ0 (m) of the axial noise σ(z, θ) = σ0 + σ2·z² + σθ/√z · θ²/(π/2 − θ)²",
    "noise_sigma_2": "σ2 (m per m²): the noise growing with the square of depth",
    "noise_sigma_theta": "σθ (m·√m): the noise growing at grazing incidence θ",
    "projector_baseline": "projector–camera distance along x (m): projector shadows beside "
    "depth steps",
    "dropout_angle_start_deg": "incidence angle (°) where steep-surface dropout starts",
    "dropout_angle_deg": "incidence angle (°) from which steep-surface dropout is certain",
    "min_range": "no data nearer than this (m)",
    "max_range": "no data farther than this (m)",
    "edge_jump": "a depth step between 4-neighbours (m)",
    "edge_dropout_prob": "chance that a pixel at such a step has no data",
    "quantisation_step": "depth unit (m)",
}


@dataclass
class RobustnessInfo(ArtifactInfo):
    """The robustness artifact: folder, manifest and its ``robustness.json`` (``data``).

    ``generation`` (the study's noisy generation artifact, drawn in the depth figure; None when
    it is not under ``data/generate/``) and ``filter_cfg`` (the figure's depth filter) are set
    by ``RobustnessSection.configure``."""

    data: dict = field(default_factory=dict)
    generation: Path | None = None
    filter_cfg: DictConfig | None = None

    @classmethod
    def load(cls, folder: Path, manifest: dict) -> RobustnessInfo:
        """Raises ``ArtifactError`` when ``robustness.json`` is missing or lacks the tables, the
        sensor model or the artifact versions."""
        try:
            # Python's json reads the NaN the study writes for undefined rates.
            data = json.loads((folder / "robustness.json").read_text())
            complete = (
                isinstance(data, dict)
                and set(ROBUSTNESS_KEYS) <= set(data)
                and all(isinstance(data[k], list) for k in ROBUSTNESS_KEYS[:3])
                and all(isinstance(data[k], dict) for k in ROBUSTNESS_KEYS[3:])
            )
        except (OSError, ValueError):
            complete = False
        if not complete:
            raise ArtifactError(
                f"{folder.name}/robustness.json (robustness) is missing or lacks "
                f"{' / '.join(ROBUSTNESS_KEYS)}: recompute it with `make robustness` "
                "(robustness.force=true)."
            )
        return cls(folder, manifest, data)


def resolve_robustness(root: Path, version: str) -> RobustnessInfo | None:
    """The robustness artifact to report, or None when ``version`` is "latest" and none exists.

    Raises ``ArtifactError`` when a named version does not exist or when its ``robustness.json``
    lacks the tables, the sensor model or the artifact versions.
    """
    return resolve_upstream(root, "robustness", version, RobustnessInfo.load)


def robustness_generation(root: Path, info: RobustnessInfo) -> Path | None:
    """The study's noisy generation artifact (drawn in the depth figure), None when it is not
    under ``root``; an artifact whose files do not match its manifest is an error."""
    version = info.data["artifacts"].get("generate_noisy")
    if not version:
        return None
    folder = Path(root) / "generate" / str(version)
    if not (folder / "manifest.json").is_file():
        return None
    return check_artifact(folder.resolve(), "report.robustness_version")


def filter_config(name: str) -> DictConfig:
    """``conf/depth_filter/<name>.yaml``."""
    return OmegaConf.load(Path(CONF_DIR) / "depth_filter" / f"{name}.yaml")


def robustness_table1_table(info: RobustnessInfo) -> Table:
    """Table 1 of each network on each input (percent; CSV with 4 decimals)."""
    headers = ["network", "input", *(h for _, h in TABLE1_COLUMNS), "predictions", "images"]
    rows = [
        [
            MODEL_LABELS.get(str(r.get("model")), str(r.get("model"))),
            str(r.get("input")),
            *(times(r.get(k)) for k, _ in TABLE1_COLUMNS),
            integer(r.get("predictions")),
            integer(r.get("images")),
        ]
        for r in info.data["table1"]
    ]
    n = len(TABLE1_COLUMNS)
    return Table(
        "robustness_table1",
        headers,
        rows,
        ["", ""] + ["{:.2f} %"] * n + ["{}", "{}"],
        csv_formats=["", ""] + ["{:.4f}"] * n + ["{}", "{}"],
        text_columns=2,
    )


def robustness_table2_table(info: RobustnessInfo) -> Table:
    """Table 2 of each planner on each input: share of images within the radius (percent)."""
    rows_in = info.data["table2"]
    key, radius = within_key(rows_in)
    headers = [
        "planner",
        "input",
        "images",
        f"within {radius} px",
        "no grasp",
        "median distance (px)",
    ]
    rows = [
        [
            ROBUSTNESS_PLANNERS.get(str(r.get("planner")), str(r.get("planner"))),
            str(r.get("input")),
            integer(r.get("images")),
            times(r.get(key)),
            integer(r.get("no_grasp")),
            number(r.get("median_distance_px")),
        ]
        for r in rows_in
    ]
    return Table(
        "robustness_table2",
        headers,
        rows,
        ["", "", "{}", "{:.2f} %", "{}", "{:.1f}"],
        csv_formats=["", "", "{}", "{:.4f}", "{}", "{:.3f}"],
        text_columns=2,
    )


def closed_loop_columns() -> list[Column]:
    """The closed-loop variants' columns: the variant, its network, overrides, split and
    trials, success rate and boxes picked with their 95 % intervals, PPH, failures by kind, how
    the trials ended, and why a variant made no attempt."""
    return [
        text_column("variant", "variant"),
        Column("network", lambda r: MODEL_LABELS.get(str(r.get("model")), str(r.get("model")))),
        Column("overrides", lambda r: str(r.get("overrides") or "-")),
        text_column("split", "split"),
        count_column("trials", "trials"),
        *trial_columns(),
    ]


def robustness_closed_loop_table(info: RobustnessInfo) -> Table:
    """The closed-loop variants of the sensor study (group ``sensor``)."""
    rows = [r for r in info.data["closed_loop"] if r.get("group") == "sensor"]
    return table_of("robustness_closed_loop", closed_loop_columns(), rows, text_columns=3)


def _versus(r: dict, ref: dict | None, key: str, factor: float) -> float | None:
    """Row ``r``'s ``key`` minus the reference row's, times ``factor``; None for the reference
    itself and where either is missing."""
    if ref is None or r is ref:
        return None
    a, b = number(r.get(key)), number(ref.get(key))
    return None if a is None or b is None else factor * (a - b)


def robustness_policies_table(info: RobustnessInfo) -> Table:
    """Sec. 8.4's policies (group ``policy``), with the change in success rate (percentage
    points) and PPH against the ``paper`` row (that row itself shows none), before the
    no-attempt reason."""
    policy = [r for r in info.data["closed_loop"] if r.get("group") == "policy"]
    ref = next((r for r in policy if r.get("variant") == REFERENCE_POLICY), None)
    *columns, reason = closed_loop_columns()
    columns += [
        Column(
            f"success rate vs. {REFERENCE_POLICY} (pp)",
            lambda r: _versus(r, ref, "success_rate", 100.0),
            "{:+.1f}",
            csv_fmt="{:.4f}",
        ),
        Column(
            f"PPH vs. {REFERENCE_POLICY}",
            lambda r: _versus(r, ref, "pph_motion", 1.0),
            "{:+.1f}",
            csv_fmt="{:.1f}",
        ),
        reason,
    ]
    return table_of("robustness_policies", columns, policy, text_columns=3)


def robustness_failures_table(info: RobustnessInfo) -> Table:
    """Failed attempts by kind of every closed-loop variant (the ``fail_*`` columns)."""
    rows_in = info.data["closed_loop"]
    kinds = list(dict.fromkeys(k for r in rows_in for k in r if k.startswith("fail_")))
    rows = [
        [str(r.get("group")), str(r.get("variant")), *(integer(r.get(k)) for k in kinds)]
        for r in rows_in
    ]
    return Table(
        "robustness_failures", ["group", "variant", *(k[5:] for k in kinds)], rows, text_columns=2
    )


def _param_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def robustness_sensor_table(info: RobustnessInfo) -> Table:
    """The sensor model's parameters, as the study recorded them."""
    rows = [[k, _param_value(v), SENSOR_MEANING.get(k)] for k, v in info.data["sensor"].items()]
    return Table("robustness_sensor_model", ["parameter", "value", "meaning"], rows, text_columns=3)


def _input_meaning(name: str) -> str:
    if name == "ideal":
        return "*ideal*: the renderer's depth"
    if name == "sensor":
        return "*sensor*: the sensor model's depth"
    head, _, filt = name.partition("+")
    if head == "sensor" and filt:
        return (
            f"*{name}*: the sensor model's depth after `conf/depth_filter/{filt}.yaml` "
            "(`pipeline/camera/depth_filter.py`)"
        )
    return f"*{name}*"


def missing_figure_note(info: RobustnessInfo) -> str:
    """Why the depth figure was not drawn: no such generation artifact, or no test image."""
    return (
        f"No depth figure: the study's noisy generation artifact "
        f"`{info.data['artifacts'].get('generate_noisy')}` "
        + (
            "has no test images."
            if info.generation is not None
            else "is not under `data/generate/` (rerun `make robustness`, which "
            "recreates it, then the report)."
        )
    )


def _closed_loop_note(rows: list[dict], trials: Any) -> str:
    """What the closed-loop variants are and which heaps they ran on: per split (``dev``,
    ``test``), its variants' trials; ``trials`` (the config's ``closed_loop_trials``) for an
    artifact made before the splits."""
    head = "The closed-loop variants are ordinary evaluation artifacts of the DCNN planner"
    splits = {r.get("split") for r in rows}
    if splits <= {None}:
        return (
            head
            + (f" ({trials} trial{'' if trials == 1 else 's'} each)" if trials is not None else "")
            + ", all on the same heaps and seeds; they differ only in the overrides shown."
        )

    def part(split: str) -> tuple[list[str], str]:
        """The split's variants and their trials ("1 trial each"; "" where none is known)."""
        mine = [r for r in rows if r.get("split") == split]
        counts = sorted({integer(r.get("trials")) for r in mine} - {None})
        each = (
            f"{' or '.join(str(n) for n in counts)} trial{'' if counts == [1] else 's'} each"
            if counts
            else ""
        )
        return [f"`{r.get('variant')}`" for r in mine], each

    out = [head + ", each on one split of the evaluation's heaps (its `split` column)."]
    # split -> (its sentence, how the trials per variant join it)
    sentences = {
        "dev": (
            "The {n} dev variants{each} share the heaps development used and differ only in the "
            "overrides shown: they compare the variants.",
            " ({})",
        ),
        "test": (
            "The test variants ({names}{each}) run on Table 3's test heaps, which nothing is "
            "chosen on: the headline figures on this sensor.",
            "; {}",
        ),
    }
    for split, (sentence, joined) in sentences.items():
        names, each = part(split)
        if names:
            each = joined.format(each) if each else ""
            out.append(sentence.format(n=len(names), names=", ".join(names), each=each))
    return " ".join(out)


def render_robustness(
    info: RobustnessInfo,
    tables: dict[str, Table],
    figure: str | None,
    figure_note: str | None = None,
) -> list[str]:
    """README lines of the robustness section (``figure``: the depth figure, if drawn;
    ``figure_note``: why it was not)."""
    out: list[str] = []
    sensor = info.data["sensor"].get("name", _study_config(info).get("sensor"))
    out += [
        _intro(info, sensor),
        "",
        "### Sensor model",
        "",
        f"The parameters of `conf/sensor/{sensor}.yaml` as the study used them "
        "(`pipeline/camera/sensor.py`).",
        "",
        tables["robustness_sensor_model"].markdown(),
    ]
    if figure:
        out += [
            "The first test image's ideal depth, its depth from this model and that depth "
            f"after `depth_filter={ROBUSTNESS_FIGURE_FILTER}`: [{figure}]({figure}).",
            "",
        ]
    elif figure_note:
        out += [figure_note, ""]
    out += [
        "### Sensor noise: Table 1",
        "",
        "Precision (%) of each network's predictions per input (Table 1's definition, "
        f'"{TABLE1_SECTION}").',
        "",
        tables["robustness_table1"].markdown(),
        "### Sensor noise: Table 2",
        "",
        "Share of test images whose optimal grasp point lies within the radius of a true "
        "surface centre, per planner and input (Table 2's measure, "
        f'"{TABLE2_SECTION}"; an image without a grasp counts as a miss).',
        "",
        tables["robustness_table2"].markdown(),
        "### Sensor noise: closed loop",
        "",
        "As in Table 3: success rate = successful grasps / attempts, boxes picked = boxes "
        "taken out / boxes dropped in, both with their Wilson 95 % score interval in brackets; "
        "PPH = successful picks per hour of simulated robot motion (what that time leaves out: "
        "Table 3's section); how the trials ended and the failed attempts by kind. A variant "
        'with no attempt says why in its last column (how its trials ended; for "no grasp", '
        "the planner's candidates and what rejected them).",
        "",
        tables["robustness_closed_loop"].markdown(),
        "### Sec. 8.4 failure cases: closed loop",
        "",
        "The paper's proposed fixes of its failure cases on ideal depth, each against the "
        f"paper's policy (the `{REFERENCE_POLICY}` row, on the same heaps): differences in "
        "success rate are percentage points, in PPH picks per hour; the columns are the closed "
        "loop table's.",
        "",
        tables["robustness_policies"].markdown(),
        "Failed attempts by kind (see Table 3's list):",
        "",
        tables["robustness_failures"].markdown(),
        "CSV versions: "
        + ", ".join(
            f"[tables/{n}.csv](tables/{n}.csv)"
            for n in (
                "robustness_sensor_model",
                "robustness_table1",
                "robustness_table2",
                "robustness_closed_loop",
                "robustness_policies",
                "robustness_failures",
            )
        )
        + ".",
        "",
    ]
    return out


def _study_config(info: RobustnessInfo) -> dict:
    return (info.manifest.get("config") or {}).get("robustness") or {}


def _intro(info: RobustnessInfo, sensor: str) -> str:
    """The section's first paragraph: the artifact, the networks, the inputs, the closed loop."""
    data = info.data
    cfg = _study_config(info)
    arts = data["artifacts"]
    inputs = list(dict.fromkeys(str(r.get("input")) for r in data["table1"] + data["table2"]))
    images = sorted({integer(r.get("images")) for r in data["table1"]} - {None})
    return (
        f"Robustness artifact `{info.version}` (`python -m pipeline.stages.robustness`): "
        "the method on "
        f"depth from the `{sensor}` sensor model instead of the ideal rendered depth, with "
        + (
            f"the network under test (train artifact `{arts.get('train_clean')}`)"
            f" and one trained on the sensor's depth (*sensor-trained*, "
            f"`{arts.get('train_noisy')}`)"
            if arts.get("train_noisy")
            else f"the network under test alone (train artifact `{arts.get('train_clean')}`; no "
            "network is trained for the sensor: `robustness.noisy_network=false`)"
        )
        + ". Tables 1 and 2 are measured on the test split of the "
        f"noisy generation artifact `{arts.get('generate_noisy')}`"
        + (f" ({', '.join(str(n) for n in images)} images)" if images else "")
        + ", the same heaps as the clean one; the labels come from the ideal depth, so they "
        "are the same for every input. Inputs: "
        + "; ".join(_input_meaning(n) for n in inputs)
        + ". "
        + _closed_loop_note(data["closed_loop"], cfg.get("closed_loop_trials"))
    )


class RobustnessSection(Section):
    name, heading, not_run = "robustness", ROBUSTNESS_SECTION, ROBUSTNESS_NOT_RUN

    def resolve(self, ctx: Context) -> RobustnessInfo | None:
        return resolve_robustness(ctx.root, ctx.requested("robustness"))

    def configure(self, info: RobustnessInfo, ctx: Context) -> dict[str, Any]:
        """What the depth figure reads besides the artifacts: the filter's parameters, and
        whether the study's noisy generation artifact is there to draw from."""
        info.generation = robustness_generation(ctx.root, info)
        info.filter_cfg = filter_config(ROBUSTNESS_FIGURE_FILTER)
        return {
            "robustness_figure": {
                "generate": info.generation.name if info.generation is not None else None,
                "depth_filter": OmegaConf.to_container(info.filter_cfg, resolve=True),
            }
        }

    def tables(self, info: RobustnessInfo, ctx: Context) -> list[Table]:
        return [
            robustness_sensor_table(info),
            robustness_table1_table(info),
            robustness_table2_table(info),
            robustness_closed_loop_table(info),
            robustness_policies_table(info),
            robustness_failures_table(info),
        ]

    def figures(self, info: RobustnessInfo, ctx: Context, folder: Path) -> dict[str, str]:
        gen_noisy = info.data["artifacts"].get("generate_noisy")
        sensor = info.data["sensor"].get("name", "sensor")
        drawn = None
        if info.generation is not None:
            drawn = figure_sensor_depth(
                info.generation,
                info.filter_cfg,
                ROBUSTNESS_FIGURE_FILTER,
                str(sensor),
                folder / ROBUSTNESS_FIGURE,
            )
        if drawn is None:
            (folder / ROBUSTNESS_FIGURE).unlink(missing_ok=True)
            return {}
        return {
            ROBUSTNESS_FIGURE: (
                f"Test image #{drawn} of generation artifact `{gen_noisy}` (the robustness "
                f"study's noisy generation): the ideal depth, the `{sensor}` model's depth "
                f"and that depth after `depth_filter={ROBUSTNESS_FIGURE_FILTER}` (magenta: "
                "no data; one colour scale)."
            )
        }

    def body(
        self, info: RobustnessInfo, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        if info is not None and ROBUSTNESS_FIGURE not in figures:
            return render_robustness(info, tables, None, missing_figure_note(info))
        return render_robustness(
            info, tables, ROBUSTNESS_FIGURE if ROBUSTNESS_FIGURE in figures else None
        )
