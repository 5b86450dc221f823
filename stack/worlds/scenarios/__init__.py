"""Named scenarios: the world a run drives in, shipped with the package (`drivestack scenarios`).

A scenario is a YAML file here: a one-line `description`, optionally a `base` scenario it extends,
and the config sections it sets. Moved to a scenario (`--scenario`), a run config's whole `highway:`
section (road and traffic) and whole `perception.sensor:` section are replaced, so nothing of another
world leaks in; everything else (agent, controller, grid, training) stays the config's. A config that
names its own `scenario:` keeps the world keys it sets itself over the scenario's, so the resolved
`config.yaml` of every results folder reads back as the config that ran.
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


@cache
def names() -> tuple[str, ...]:
    """The shipped scenarios' names (listed once: validators ask for every name they check)."""
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


def apply(name: str, config: dict[str, Any], keep_own: bool = False) -> dict[str, Any]:
    """`config` (a run config as data) in scenario `name`; ValueError for an unknown name. With
    `keep_own`, the `highway:` and `perception.sensor:` keys `config` sets are laid over the
    scenario's (a config naming its own scenario); without, the scenario's replace them."""
    scenario = copy.deepcopy(_read(name))
    perception = config.get("perception", {})
    own_road = config.get("highway") if keep_own else None
    applied = {**config, "scenario": name, "highway": laid_over(scenario["highway"], own_road)}
    if isinstance(perception, dict):
        own_sensor = perception.get("sensor") if keep_own else None
        sensor = laid_over(scenario.get("perception", {}).get("sensor", {}), own_sensor)
        applied["perception"] = {**perception, "sensor": sensor}
    return applied


def laid_over(base: dict[str, Any], own: Any) -> Any:
    """`own` laid over `base`, section by section (a key `own` sets wins; lists are replaced
    whole); `own` as it is when either is not a section (validation then names the bad value)."""
    if own is None:
        return base
    if not isinstance(own, dict):
        return own
    return base | {
        key: laid_over(base[key], value) if isinstance(base.get(key), dict) else value
        for key, value in own.items()
    }
