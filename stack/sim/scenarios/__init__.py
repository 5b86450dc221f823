"""Named scenarios: the world a run drives in, shipped with the package (`drivestack scenarios`).

A scenario is a YAML file here: a one-line `description`, optionally a `base` scenario it extends,
and the config sections it sets. Applied to a run config, a scenario replaces the whole `highway:`
section (road and traffic) and the whole `perception.sensor:` section, so nothing of another world
leaks in; everything else (agent, controller, grid, training) stays the config's.
"""

from __future__ import annotations

import copy
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from records import unknown_name

FOLDER = Path(__file__).parent
SECTIONS = ("highway", "perception")
"""Config sections a scenario may set (perception: only `sensor`)."""


def names() -> tuple[str, ...]:
    return tuple(sorted(path.stem for path in FOLDER.glob("*.yaml")))


@cache
def _read(name: str) -> dict[str, Any]:
    if name not in names():
        raise ValueError(unknown_name("scenario", name, names()))
    data = yaml.safe_load((FOLDER / f"{name}.yaml").read_text())
    base = data.pop("base", None)
    if base is not None:
        data = {
            **_read(base),
            "description": data["description"],
            **{k: data[k] for k in SECTIONS if k in data},
        }
    return data


def description(name: str) -> str:
    return str(_read(name)["description"])


def road(name: str) -> dict[str, Any]:
    """Scenario `name`'s `highway:` section (road and traffic), as data."""
    return copy.deepcopy(_read(name)["highway"])


def apply(name: str, config: dict[str, Any]) -> dict[str, Any]:
    """`config` (a run config as data) in scenario `name`; ValueError for an unknown name."""
    scenario = copy.deepcopy(_read(name))
    applied = {**config, "scenario": name, "highway": scenario["highway"]}
    perception = config.get("perception", {})
    if isinstance(perception, dict):
        applied["perception"] = {**perception, "sensor": scenario.get("perception", {}).get("sensor", {})}
    return applied
