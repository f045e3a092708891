"""What a section of the report is (``Section``) and what it may read (``Context``).

A section reports one upstream artifact: it resolves and checks it, makes its tables and
figures, writes its part of the README and names its metrics. ``pipeline.report.stage`` calls,
for every section of ``REPORT_SECTIONS``:

1. ``resolve(ctx)``: the artifact's info, or None for an optional artifact that does not exist
   (stored in ``ctx.found[name]``, so later sections can match it);
2. ``configure(info, ctx)``: entries the section adds to the stage config (the version key);

and, inside the artifact being built, for a resolved artifact only:

3. ``tables(info, ctx)``, then ``figures(info, ctx, folder)`` (files written under ``folder``,
   the artifact's; returns ``{relative path: caption}``);

and for every section:

4. ``markdown(info, tables, figures)``: its README lines (a "not run yet" line for None);
5. ``metrics(info)``: its entries in the manifest's metrics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from pipeline.report.tables import Table
from pipeline.report.upstream import ArtifactInfo
from pipeline.runtime.cli import data_root


@dataclass
class Context:
    """One run of the report: its config and the upstream artifacts resolved so far."""

    cfg: DictConfig
    found: dict[str, ArtifactInfo | None] = field(default_factory=dict)  # by section name

    @property
    def root(self) -> Path:
        """The data folder (``paths.data``): ``<root>/<stage>/<version>``."""
        return data_root(self.cfg)

    @property
    def models(self) -> Path:
        """The models folder (``paths.models``), where the train artifacts are."""
        return Path(self.cfg.paths.models)

    @property
    def num_samples(self) -> int:
        """``report.num_sample_images``: depth images drawn in the sample figures."""
        return int(self.cfg.report.num_sample_images)

    def requested(self, name: str) -> str:
        """``report.<name>_version``: the version to report ("latest" or a key)."""
        return str(self.cfg.report[f"{name}_version"])

    def version(self, name: str) -> str | None:
        """The version of the resolved ``name`` artifact, None when there is none."""
        info = self.found.get(name)
        return info.version if info is not None else None


class Section:
    """One section of the report, for the upstream artifact of stage ``name``."""

    name: str = ""  # the upstream stage: its key in the report's upstream versions
    # The paper's table that the section reports (for the "Paper tables" sentence), and the
    # README heading it is under. None: the section reports none.
    paper_table: str | None = None
    heading: str = ""
    not_run: str = ""  # what the README says under the heading when there is no artifact

    def paper_table_sentence(self, info: ArtifactInfo | None) -> str:
        """Where the README shows the paper's table, or the command that makes it."""
        if info is not None:
            return f'{self.paper_table} is reported above, in "{self.heading}". '
        return f"{self.paper_table} will appear above once `make {self.name}` has run. "

    def resolve(self, ctx: Context) -> ArtifactInfo | None:
        raise NotImplementedError

    def configure(self, info: ArtifactInfo, ctx: Context) -> dict[str, Any]:
        return {}

    def tables(self, info: ArtifactInfo, ctx: Context) -> list[Table]:
        return []

    def figures(self, info: ArtifactInfo, ctx: Context, folder: Path) -> dict[str, str]:
        return {}

    def markdown(
        self, info: ArtifactInfo | None, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        """README lines of the section: its heading, then ``body``, or ``not_run`` when the
        stage's artifact does not exist."""
        head = [f"## {self.heading}", ""]
        return head + ([self.not_run, ""] if info is None else self.body(info, tables, figures))

    def body(
        self, info: ArtifactInfo, tables: dict[str, Table], figures: dict[str, str]
    ) -> list[str]:
        """README lines under the heading, for an existing artifact."""
        raise NotImplementedError

    def metrics(self, info: ArtifactInfo | None) -> dict[str, Any]:
        return {f"{self.name}_version": info.version if info is not None else None}
