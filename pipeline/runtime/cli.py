"""Shared plumbing for the stages' thin command-line wrappers."""

from __future__ import annotations

import copy
import functools
import importlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from omegaconf import DictConfig, OmegaConf

from pipeline.artifacts.fingerprint import REPO_ROOT, stage_module
from pipeline.config import register_configs

CONF_DIR = str(REPO_ROOT / "conf")
# The stages of ``make reproduce``, in its order (the report comes last).
REPRODUCE_STAGES = (
    "generate",
    "label",
    "train",
    "baseline",
    "evaluate",
    "unseen",
    "ablation",
    "robustness",
)

if not OmegaConf.has_resolver("repo_root"):
    OmegaConf.register_new_resolver("repo_root", lambda: str(REPO_ROOT))
register_configs()


def default_workers(requested: int) -> int:
    """``requested`` if positive, else the number of cores this process may use."""
    if requested > 0:
        return requested
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def data_root(cfg: DictConfig) -> Path:
    return Path(cfg.paths.data)


class MissingLibraryError(ImportError):
    """A package, or a system library it loads, cannot be imported; the message gives the fix."""


# Packages that need a system library pip does not install: the library and how to install it.
SYSTEM_LIBRARIES = {
    "open3d": (
        "libusb-1.0",
        "`sudo apt-get install libusb-1.0-0` (Debian/Ubuntu), or run "
        "`bash scripts/setup.sh` as root",
    )
}


def import_with_fix(name: str) -> ModuleType:
    """``import <name>``, or a ``MissingLibraryError`` that says how to make it importable.

    Use it for packages with system-library needs (:data:`SYSTEM_LIBRARIES`): open3d fails
    with an OSError or ImportError about ``libusb-1.0.so.0`` when the Debian package
    ``libusb-1.0-0`` is missing.
    """
    try:
        return importlib.import_module(name)
    except (ImportError, OSError) as e:
        library, fix = SYSTEM_LIBRARIES.get(
            name, (None, "reinstall the environment: `make setup` (or `bash scripts/setup.sh`)")
        )
        needs = f" (it needs the system library {library})" if library else ""
        raise MissingLibraryError(
            f"cannot import {name}{needs}: {type(e).__name__}: {e}. Fix: {fix}.", name=name
        ) from e


def conf_file(group: str, name: str) -> Path:
    """The YAML file of option ``name`` of config group ``group`` (``conf/<group>/<name>.yaml``)."""
    return Path(CONF_DIR) / group / f"{name}.yaml"


def own_overrides(exclude_prefix: str) -> list[str]:
    """This command's own Hydra overrides, minus those of ``<exclude_prefix>.*`` (a study stage
    passes the rest on to every stage it runs); none outside ``@hydra.main``."""
    try:
        from hydra.core.hydra_config import HydraConfig

        task = list(HydraConfig.get().overrides.task)
    except ValueError:  # not under @hydra.main (tests, notebooks)
        return []
    return [o for o in task if not o.lstrip("+~").startswith(exclude_prefix + ".")]


def scale_overrides(cfg: DictConfig, overrides: list[str] | None) -> list[str]:
    """``overrides`` with this config's ``experiment`` and ``paths.root`` added where they are
    not given: what a study stage passes to the stages it runs."""
    base = list(overrides or [])
    if not any(o.startswith("experiment=") for o in base):
        base.insert(0, f"experiment={cfg.experiment}")
    if not any(o.startswith("paths.root=") for o in base):
        base.append(f"paths.root={cfg.paths.root}")
    return base


def stage_main(stage_fn: Callable[[DictConfig], object]) -> Callable[[DictConfig], None]:
    """Wrap a stage function for ``@hydra.main``: known errors print one clear line, exit 2.

    Known errors: ``ArtifactError`` (missing, mistyped or corrupted artifact),
    ``MissingLibraryError`` (``import_with_fix``), ``FileNotFoundError`` and ``ValueError``
    (bad input or configuration). Anything else is a bug and keeps its traceback.
    """
    from pipeline.artifacts.store import ArtifactError

    @functools.wraps(stage_fn)
    def main(cfg: DictConfig) -> None:
        try:
            stage_fn(cfg)
        except (ArtifactError, MissingLibraryError, FileNotFoundError, ValueError) as e:
            message = " ".join(str(e).split())  # one line
            print(f"error: {message}", file=sys.stderr)
            sys.exit(2)

    return main


def stage_command(
    config_name: str, stage_fn: Callable[..., object], *, study: bool = False
) -> Callable[[], None]:
    """The command line of a stage, ``python -m <its module> [overrides]``: Hydra composes
    ``conf/<config_name>.yaml`` with the command line's overrides and calls ``stage_fn`` on the
    result, through ``stage_main``. ``study``: ``stage_fn(cfg, overrides)`` also gets the command
    line's own overrides but its own section's (``own_overrides``), to pass on to every stage it
    runs."""
    import hydra

    @functools.wraps(stage_fn)  # Hydra names the job after the stage's module
    def run(cfg: DictConfig) -> object:
        return stage_fn(cfg, own_overrides(config_name)) if study else stage_fn(cfg)

    entry = hydra.main(config_path=CONF_DIR, config_name=config_name, version_base="1.3")
    return entry(stage_main(run))


def compose(config_name: str, overrides: list[str]) -> DictConfig:
    """The config a stage gets from ``python -m pipeline.<config_name> <overrides>``.

    For tests, benchmarks, notebooks and the studies' sub-stages; raises Hydra's errors on
    unknown keys or bad types. The result is :func:`compose_uncached`'s: Hydra composes the
    files that the config-group overrides (``experiment=smoke``, ``sensor=sr300``) choose, then
    applies the value overrides (``paths.root=...``, ``+key=...``, ``~key``) to the result. This
    process keeps the first step's result per config name and group choices, for as long as no
    file in ``conf/`` changes, and applies the value overrides to a copy of it with Hydra's own
    override code: a composition differing in values only takes a copy instead of a full one.
    Overrides of Hydra's own settings, of a ``@package``, sweeps and dict values of a group go
    the uncached way.
    """
    split = _group_and_value_overrides(overrides)
    if split is None:
        return compose_uncached(config_name, overrides)
    groups, values = split
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    cfg = copy.deepcopy(_composed_groups(config_name, tuple(groups), _conf_files_state()))
    ConfigLoaderImpl._apply_overrides_to_config(values, cfg)
    return cfg


def compose_uncached(config_name: str, overrides: list[str]) -> DictConfig:
    """Hydra's composition of ``conf/<config_name>.yaml`` with ``overrides``, from the files."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(version_base="1.3", config_dir=CONF_DIR):
            return hydra_compose(config_name=config_name, overrides=overrides)
    finally:
        GlobalHydra.instance().clear()


@functools.lru_cache(maxsize=64)
def _composed_groups(config_name: str, groups: tuple[str, ...], conf_state: tuple) -> DictConfig:
    """``compose_uncached(config_name, groups)``, kept per ``conf_state`` of the files (never
    returned itself: :func:`compose` copies it)."""
    return compose_uncached(config_name, list(groups))


def _conf_files_state() -> tuple:
    """(relative path, modification time, size) of every file in ``conf/``."""
    root = Path(CONF_DIR)
    return tuple(
        (str(p.relative_to(root)), st.st_mtime_ns, st.st_size)
        for p in sorted(root.rglob("*"))
        if p.is_file() and (st := p.stat())
    )


def _group_and_value_overrides(overrides: list[str]):
    """(the config-group overrides as given, the parsed value overrides), split as Hydra splits
    them (an override of a key naming a group folder of ``conf/`` chooses a config file, unless
    its value is a dict); None when an override needs Hydra's whole composition (one of Hydra's
    own settings, a ``@package``, a sweep or a dict value for a group)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    try:
        parsed = OverridesParser.create().parse_overrides(list(overrides))
    except HydraException:
        return None  # Hydra raises its own error on the uncached way
    groups, values = [], []
    for line, o in zip(overrides, parsed, strict=True):
        if o.is_hydra_override() or o.is_sweep_override() or o.package is not None:
            return None
        key = o.key_or_group
        if "." not in key and (Path(CONF_DIR) / key).is_dir():
            if isinstance(o.value(), dict):
                return None
            groups.append(line)
        else:
            values.append(o)
    return groups, values


def run_named_stage(stage: str, overrides: list[str], caller: str) -> Path:
    """Run (or reuse) ``stage_module(stage)`` with these Hydra overrides; its artifact folder.

    ``caller``: the study's name, printed with the command. Raises ``RuntimeError`` when the
    stage returns no folder (a non-zero torchrun rank)."""
    fn = getattr(importlib.import_module(stage_module(stage)), stage)
    print(f"[{caller}] {stage} {' '.join(overrides)}", flush=True)
    out = fn(compose(stage, list(overrides)))
    if out is None:
        raise RuntimeError(
            f"[{caller}] the {stage} stage returned no artifact (a non-zero torchrun rank?)"
        )
    return Path(out)
