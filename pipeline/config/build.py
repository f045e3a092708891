"""Build an algorithm's settings dataclass straight from a section of the composed config.

The algorithm modules (``pipeline.dexnet``, ``pipeline.servo``, …) take plain dataclasses, so
they run without Hydra; their values live in ``conf/`` only. ``from_section`` fills such a
dataclass from the section whose keys are its field names, so no code copies values field by
field.
"""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

from omegaconf import DictConfig, OmegaConf

T = TypeVar("T")


def from_section(cls: type[T], section: Any, **given: Any) -> T:
    """An instance of the dataclass ``cls``: each field is ``given[name]`` when given, else
    ``section[name]`` (as a plain Python value). ``section``: a config node (``DictConfig``), its
    schema dataclass (a section of ``OmegaConf.to_object(cfg)``) or a dict. Keys of ``section`` that
    ``cls`` has no field
    for are ignored (one section may configure several classes).

    Raises ``KeyError`` naming the field and the section's keys when a field is in neither, and
    ``TypeError`` when ``given`` names a field ``cls`` does not have.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise TypeError(f"{cls.__name__} has no field(s) {unknown}")
    if isinstance(section, DictConfig):
        values = OmegaConf.to_container(section, resolve=True)
    elif dataclasses.is_dataclass(section):  # a section of ``OmegaConf.to_object(cfg)``
        values = {f.name: getattr(section, f.name) for f in dataclasses.fields(section)}
    else:
        values = dict(section)
    kwargs = {}
    for name in names:
        if name in given:
            kwargs[name] = given[name]
        elif name in values:
            kwargs[name] = values[name]
        else:
            raise KeyError(
                f"{cls.__name__}.{name} is in neither the config section (keys: "
                f"{sorted(values)}) nor the given values; add it to the section's "
                "YAML file in conf/"
            )
    return cls(**kwargs)
