"""Run configuration: YAML -> validated pydantic models, before any work starts.

Every error is one line naming the file and the dotted key, e.g.
`configs/x.yaml: highway.lanes_count: must be >= 1 (got 0)`.
"""

from __future__ import annotations

from functools import cache
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import Field, ValidationError, model_validator

from controllers.config import ControllerConfig
from perception.grid import OccupancyGridBuilder
from perception.sensor import SensorConfig
from planner.mobil import prior_problem
from planner.networks import LANE_NETWORK, lane_problem
from records import SEED_LIMIT, GridConfig
from stack.runtime.files import write_text
from stack.runtime.yaml_text import strict_yaml
from stack.settings.checks import boolean_mismatch
from stack.settings.history import with_former_values
from stack.settings.layers import NOT_GRID, PerceptionConfig, PlannerConfig
from stack.settings.train import Strict, TrainConfig
from stack.settings.world import HighwayConfig, SimConfig
from stack.worlds import scenarios
from stack.worlds.drivers import HIGHWAY_ENV, STOCK_POPULATIONS, stock_drives


class ConfigError(ValueError):
    """A configuration that cannot run; the message is one line for the user."""


class RunConfig(Strict):
    scenario: str | None = Field(None, description="the named world applied (stack.worlds.scenarios)")
    seed: int = Field(0, ge=0, le=SEED_LIMIT - 1_000_000, description="seed of the first episode")
    episodes: int = Field(5, ge=1, le=1_000_000)
    highway: HighwayConfig = HighwayConfig()
    sim: SimConfig = SimConfig()
    control_rate_hz: float = Field(15.0, gt=0, le=1000)
    decision_period_s: float = Field(1.0, gt=0, le=60, description="[s]")
    perception: PerceptionConfig = PerceptionConfig()
    planner: PlannerConfig = PlannerConfig()
    controller: ControllerConfig = ControllerConfig()
    train: TrainConfig = TrainConfig()

    @model_validator(mode="after")
    def _consistent_timing(self) -> RunConfig:
        if self.control_rate_hz != self.highway.simulation_frequency:
            raise ValueError(
                f"control_rate_hz: must equal highway.simulation_frequency "
                f"({self.highway.simulation_frequency} Hz), got {self.control_rate_hz}"
            )
        if self.decision_period_s < 1.0 / self.control_rate_hz - 1e-12:
            raise ValueError(
                f"decision_period_s: must be at least one control tick "
                f"({1.0 / self.control_rate_hz:.4f} s), got {self.decision_period_s}"
            )
        return self

    @model_validator(mode="after")
    def _backend_drives_the_drivers(self) -> RunConfig:
        drivers = drivers_of(self.highway)
        if self.sim.backend != "vector" and not stock_drives(drivers):
            raise ValueError(
                f"sim.backend: the {self.sim.backend} backend drives {', '.join(STOCK_POPULATIONS)} drivers "
                f"only (no habits), not {drivers!r}: use the vector backend"
            )
        return self

    @model_validator(mode="after")
    def _mobil_sees_its_lanes(self) -> RunConfig:
        if problem := prior_problem(grid_config(self), self.train.encoding, self.train.mobil_prior):
            raise ValueError(f"train.mobil_prior: {problem}")
        return self

    @model_validator(mode="after")
    def _lane_network_reads_its_grid(self) -> RunConfig:
        if self.train.network == LANE_NETWORK and (
            problem := lane_problem(grid_config(self), self.train.encoding)
        ):
            raise ValueError(f"train.network: {problem}")
        return self

    @model_validator(mode="after")
    def _one_encoding_for_the_mix(self) -> RunConfig:
        roads = named_roads(self.train.scenarios)
        self.check_one_encoding(roads)
        if (demonstrations := self.train.demonstrations) is not None and demonstrations.scenarios:
            own = f"{self.scenario} (the run's road)" if self.scenario else "the configured road"
            learner = {f"{name} (trained)": road for name, road in roads.items()} or {own: self.highway}
            self.check_one_encoding(
                learner | named_roads(demonstrations.scenarios), "train.demonstrations.scenarios"
            )
        return self

    def check_one_encoding(self, roads: dict[str, HighwayConfig], key: str = "train.scenarios") -> None:
        """ValueError (one line, blaming `key`) unless `train.encoding` has one size on every lane
        count of the named `roads` (one observation space for every training episode)."""
        lanes = {(name, count) for name, road in roads.items() for count in road.lane_counts}
        if len(lanes) < 2:
            return
        grid = OccupancyGridBuilder(GridConfig(**self.perception.model_dump(exclude=NOT_GRID)))
        sizes = {(name, count): grid.space(self.train.encoding, count).shape for name, count in lanes}
        if len(set(sizes.values())) > 1:
            raise ValueError(
                f"{key}: the {self.train.encoding} encoding has a different size on "
                f"{' and '.join(sorted({name for name, _ in sizes}))} (lane counts "
                f"{sorted({count for _, count in lanes})}); use perception lanes: ego with lane_code: sides"
            )

    @property
    def dt(self) -> float:
        """One control tick = one physics frame [s]."""
        return 1.0 / self.control_rate_hz

    @property
    def decision_ticks(self) -> int:
        """Control ticks between two decisions."""
        return max(1, round(self.decision_period_s * self.control_rate_hz))


class Null:
    """The value of an override that sets its key to null (`--set KEY=null`); None as an
    override means "not given"."""

    def __repr__(self) -> str:
        return "null"


NULL = Null()
MAX_CONFIG_BYTES = 1_000_000
"""Largest config file read [bytes]."""
MAX_QUOTE = 80
"""Longest quote of an offending value in an error message [characters]."""


def one_line(error: ValidationError, source: str, labels: dict[str, str]) -> str:
    first = error.errors()[0]
    key = ".".join(str(part) for part in first["loc"])
    message = first["msg"].removeprefix("Value error, ")
    named = message.split(":", 1)[0] if ":" in message else ""
    source = label_for(labels, f"{key}.{named}" if key and named.isidentifier() else key or named, source)
    if first["type"] == "extra_forbidden":
        message = "unknown key"
    elif first["type"] != "value_error" and not isinstance(first.get("input"), dict):
        message = f"{message} (got {repr(first.get('input'))[:MAX_QUOTE]})"
    return printable(f"{source}: {key}: {message}" if key else f"{source}: {message}")


def label_for(labels: dict[str, str], key: str, source: str) -> str:
    """What to name for an error at dotted `key`: the label of the key or of the nearest section
    holding it (`--set highway.traffic=...` for `highway.traffic.classes.0.share`), else of a key
    inside it (`--set hïghway.duration=5` for the unknown section `hïghway`), else `source`."""
    parts = key.split(".")
    found = (labels.get(".".join(parts[:end])) for end in range(len(parts), 0, -1))
    inside = (label for dotted, label in labels.items() if dotted.startswith(f"{key}."))
    return next(chain((label for label in found if label is not None), inside), source)


def printable(message: str, limit: int = 300) -> str:
    """`message` on one line: control characters escaped, at most `limit` characters."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)[:limit]


def _set_dotted(data: dict[str, Any], dotted: str, value: Any, source: str) -> None:
    node = data
    *parents, leaf = dotted.split(".")
    for depth, part in enumerate(parents):
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ConfigError(
                f"{source}: {'.'.join(parents[: depth + 1])}: not a section, cannot set {dotted}"
            )
    node[leaf] = value


def config_text(config: RunConfig, comment: str = "", exclude: dict | None = None) -> str:
    """The resolved `config` as YAML, loadable with `--config` (a `# comment` first), without the
    keys `exclude` names (pydantic's nested form)."""
    header = "".join(f"# {line}\n" for line in comment.splitlines())
    return header + yaml.safe_dump(config.model_dump(mode="json", exclude=exclude), sort_keys=False)


def write_config(config: RunConfig, path: Path, comment: str = "") -> None:
    write_text(path, config_text(config, comment))


def named_roads(mix: dict[str, float]) -> dict[str, HighwayConfig]:
    """The road of each scenario of `mix`, by name."""
    return {name: scenario_road(name) for name in mix}


@cache
def scenario_road(name: str) -> HighwayConfig:
    """Scenario `name`'s road and traffic, resolved once per process: every world of a training
    mix is validated, and each validation checks the roads of the whole mix."""
    return HighwayConfig(**scenarios.road(name))


def in_scenario(config: RunConfig, name: str) -> RunConfig:
    """`config` moved to scenario `name` (its world replaced, its traffic's drivers and everything
    else kept; the exit road spawns its own traffic, with highway-env's drivers)."""
    data = scenarios.apply(name, config.model_dump(mode="json"))
    drivers = drivers_of(config.highway)
    if drivers != HIGHWAY_ENV and data["highway"].get("road") != "exit":
        data = with_drivers(data, drivers, "traffic")
    return RunConfig.model_validate(data)


def drivers_of(highway: HighwayConfig) -> str | dict[str, float]:
    """The driver population of a world (`highway.random_traffic` or `highway.traffic`)."""
    for section in (highway.random_traffic, highway.traffic):
        if section is not None:
            return section.drivers
    return HIGHWAY_ENV


def training_worlds(config: RunConfig) -> dict[str, RunConfig]:
    """The worlds a training episode draws from, by name: `config` moved to each scenario of its
    mix (`train.scenarios`), else `config` itself (named by its scenario, or "configured"). The one
    place a mix is resolved; the decision MDP and its validation read what it returns."""
    if not config.train.scenarios:
        return {config.scenario or "configured": config}
    return {name: in_scenario(config, name) for name in config.train.scenarios}


def demonstration_worlds(config: RunConfig) -> RunConfig:
    """`config` with `train.demonstrations.scenarios` as its world mix, if it names one."""
    demonstrations = config.train.demonstrations
    if demonstrations is None or not demonstrations.scenarios:
        return config
    return config.model_copy(
        update={"train": config.train.model_copy(update={"scenarios": demonstrations.scenarios})}
    )


def build_config(
    data: dict[str, Any], source: str = "config", labels: dict[str, str] | None = None, **overrides: Any
) -> RunConfig:
    """Validate `data` in its scenario with dotted-key `overrides` applied (None values are
    ignored, `NULL` sets null): `scenario` in `overrides` moves `data` to that world, a
    `scenario` of `data`'s own keeps the world keys `data` sets over it
    (`stack.worlds.scenarios.apply`). An error
    in a key that `labels` names (dotted key -> e.g. the CLI option that set it) blames that label
    instead of `source`."""
    labels = labels or {}
    data = with_former_values(dict(data), RunConfig)
    moved_to = overrides.pop("scenario", None)
    scenario = moved_to or data.get("scenario")
    if scenario is not None:
        blamed = labels.get("scenario", source)
        if not isinstance(scenario, str):
            raise ConfigError(
                f"{blamed}: scenario: expected a scenario name, one of {', '.join(scenarios.names())}"
            )
        try:
            data = scenarios.apply(scenario, data, keep_own=moved_to is None)
        except ValueError as error:
            raise ConfigError(f"{blamed}: scenario: {error}") from None
    drivers = overrides.pop("traffic", None)
    if drivers is not None:
        data = with_drivers(data, drivers, labels.get("traffic", source))
        blamed_for_drivers = labels.get("traffic", source)
        labels = labels | {f"highway.{key}.drivers": blamed_for_drivers for key in DRIVER_SECTIONS}
    for dotted, value in overrides.items():
        if value is not None:
            key = dotted.replace("__", ".")
            _set_dotted(data, key, None if value is NULL else value, labels.get(key, source))
    if mismatch := boolean_mismatch(RunConfig, data):
        key, message = mismatch
        raise ConfigError(printable(f"{label_for(labels, key, source)}: {key}: {message}"))
    try:
        return RunConfig.model_validate(data)
    except ValidationError as error:
        raise ConfigError(one_line(error, source, labels)) from None


DRIVER_SECTIONS = ("traffic", "random_traffic")
"""The `highway` sections that hold a driver population (`drivers`)."""


def with_drivers(data: dict[str, Any], drivers: object, blamed: str) -> dict[str, Any]:
    """`data` with the driver population `drivers` (`--traffic`) in its world's traffic section
    (`highway.random_traffic` or `highway.traffic`, validated with it; a world without either,
    highway-env's own vehicles, gets a `traffic` section of its drivers alone)."""
    highway = data.get("highway")
    for key in DRIVER_SECTIONS:
        section = highway.get(key) if isinstance(highway, dict) else None
        if isinstance(section, dict):
            assert isinstance(highway, dict)
            return {**data, "highway": {**highway, key: {**section, "drivers": drivers}}}
    if drivers == HIGHWAY_ENV:
        return data
    if highway is not None and not isinstance(highway, dict):
        raise ConfigError(f"{blamed}: expected a highway section to draw the drivers in")
    return {**data, "highway": {**(highway or {}), "traffic": {"drivers": drivers}}}


def read_mapping(path: Path | str) -> dict[str, Any]:
    """The YAML mapping in the file at `path` (at most MAX_CONFIG_BYTES, no anchors or aliases);
    raise ConfigError (one line naming the file) on any problem."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such config file")
    if path.stat().st_size > MAX_CONFIG_BYTES:
        raise ConfigError(f"{path}: {path.stat().st_size} bytes; a config is at most {MAX_CONFIG_BYTES}")
    try:
        data = strict_yaml(path.read_text(encoding="utf-8")) or {}
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text") from None
    except OSError as error:
        raise ConfigError(f"{path}: cannot read ({error.strerror})") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        problem = getattr(error, "problem", None)
        reason = f" ({str(problem)[:MAX_QUOTE]})" if problem else ""
        raise ConfigError(f"{path}: not valid YAML{where}{reason}") from None
    except ValueError as error:  # an integer of more digits than Python converts
        raise ConfigError(f"{path}: a value it holds cannot be read ({str(error)[:MAX_QUOTE]})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of keys at the top level")
    return data


def load_config(path: Path | str, labels: dict[str, str] | None = None, **overrides: Any) -> RunConfig:
    """Read a YAML run config, apply CLI overrides, validate; raise ConfigError on any problem. A
    relative `train.init_model` or `train.demonstrations.expert_model` in the file that names a
    file beside it is that file, so a packaged training config finds its models from any working
    directory."""
    data = read_mapping(path)
    train = data.get("train")
    if isinstance(train, dict):
        _beside(train, "init_model", Path(path))
        if isinstance(demonstrations := train.get("demonstrations"), dict):
            _beside(demonstrations, "expert_model", Path(path))
    return build_config(data, str(path), labels, **overrides)


def _beside(section: dict[str, Any], key: str, config_file: Path) -> None:
    """`section[key]`, a relative model file that lies beside `config_file`, made that file."""
    if isinstance(name := section.get(key), str) and (beside := config_file.parent / name).is_file():
        section[key] = str(beside.resolve())


def grid_config(config: RunConfig) -> GridConfig:
    """The perception grid `config` asks for (its `perception` section without the sensor)."""
    return GridConfig(**config.perception.model_dump(exclude=NOT_GRID))


SENSOR_DRAW_STREAM = 7
"""The generator stream `episode_sensor` draws a random world's sensor from (beside the seed)."""


def episode_sensor(config: RunConfig, seed: int) -> SensorConfig:
    """The sensor episode `seed` is seen through: `perception.sensor`, or, on a road of random
    traffic, that sensor with its noise, missed detections and phantoms drawn from the ranges of
    `highway.random_traffic` (from the seed alone, so every backend and process draws the same)."""
    ranges, sensor = config.highway.random_traffic, config.perception.sensor
    if ranges is None:
        return sensor
    rng = np.random.default_rng((seed, SENSOR_DRAW_STREAM))
    drawn = ("position_noise_m", "miss_probability", "false_positives")
    return sensor.model_copy(update={name: float(rng.uniform(*getattr(ranges, name))) for name in drawn})
