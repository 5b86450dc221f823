"""Run configuration: YAML -> validated pydantic models, before any work starts.

Every error is one line naming the file and the dotted key, e.g.
`configs/x.yaml: highway.lanes_count: must be >= 1 (got 0)`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from controllers.config import ControllerConfig
from perception.sensor import SensorConfig
from planner.networks import NET_ARCHS
from planner.safety import SafetyConfig
from records import (
    AGENT_NAMES,
    ENCODINGS,
    LEARNED_AGENTS,
    AgentName,
    Encoding,
    GridConfig,
    LearnedAgentName,
    one_of,
)
from stack.sim import scenarios
from stack.sim.settings import HighwayConfig, SimConfig


class ConfigError(ValueError):
    """A configuration that cannot run; the message is one line for the user."""


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class PerceptionConfig(GridConfig):
    """The occupancy grid (perception.grid.GridConfig's keys), the sensor model, and who sees it:
    by default the agent, the safety layer and the adaptive cruise all act on the perceived world;
    `control_on_ground_truth` lets safety and cruise read the simulator's truth (an ablation)."""

    sensor: SensorConfig = SensorConfig()
    control_on_ground_truth: bool = False


class OracleConfig(Strict):
    """The tree's depth (decisions), the look-ahead horizon [s], the lane-change margin [m] and the
    agent that drives after the tree's last decision."""

    depth: int = Field(2, ge=1, le=3)
    horizon_s: float = Field(10.0, gt=0, le=30)
    margin_m: float = Field(1.0, ge=0)
    base: Literal["keep-lane", "mobil", "rule"] = "keep-lane"


class PlannerConfig(Strict):
    agent: Annotated[AgentName, one_of("agent", AGENT_NAMES)] = "rule"
    model: Path | None = None
    safety: SafetyConfig = SafetyConfig()
    oracle: OracleConfig = OracleConfig()


class RewardConfig(Strict):
    """Per decision step: alive x (seconds elapsed / decision period), plus speed_weight x that
    fraction x the ego's mean speed over the step mapped from speed_range [m/s] to [0, 1]; a crash
    gives `collision` instead; `lane_change` is subtracted whenever the agent asks for a lane change
    (granted or masked), a margin like MOBIL's threshold so it asks only when the change pays. The
    paper's reward is alive = 1, collision = -1, speed_weight = 0, lane_change = 0."""

    alive: float = 1.0
    collision: float = -1.0
    speed_weight: float = Field(0.0, ge=0)
    speed_range: tuple[float, float] = (20.0, 30.0)
    lane_change: float = Field(0.0, ge=0)

    @field_validator("speed_range")
    @classmethod
    def _ordered(cls, bounds: tuple[float, float]) -> tuple[float, float]:
        if not bounds[0] < bounds[1]:
            raise ValueError(f"must be (low, high) with low < high, got {list(bounds)}")
        return bounds


class ValidationConfig(Strict):
    """The paper's real-time validation: short and long periods in environment steps."""

    short_every: int = Field(2_000, ge=1)
    short_episodes: int = Field(3, ge=1)
    long_every: int = Field(10_000, ge=1)
    long_episodes: int = Field(10, ge=1)
    seed: int = Field(100_000, ge=0)


class TrainConfig(Strict):
    """`drivestack train`: algorithm, budget, network, SB3 hyper-parameters, reward, validation."""

    algorithm: Annotated[LearnedAgentName, one_of("algorithm", LEARNED_AGENTS)] = "ddqn"
    steps: int = Field(50_000, ge=1)
    envs: int = Field(1, ge=1, le=64, description="environments stepped in parallel processes (DDQN / DQN)")
    encoding: Annotated[Encoding, one_of("encoding", ENCODINGS)] = "observation"
    network: Annotated[str, one_of("network", tuple(NET_ARCHS))] = "shallow"
    learning_rate: float = Field(5e-4, gt=0)
    buffer_size: int = Field(50_000, ge=1)
    learning_starts: int = Field(1_000, ge=0)
    batch_size: int = Field(64, ge=1)
    gamma: float = Field(0.95, gt=0, le=1)
    train_freq: int = Field(1, ge=1)
    target_update_interval: int = Field(500, ge=1)
    exploration_fraction: float = Field(0.3, gt=0, le=1)
    exploration_final_eps: float = Field(0.05, ge=0, le=1)
    tabular_alpha: float = Field(0.1, gt=0, le=1)
    tabular_epsilon: float = Field(0.2, ge=0, le=1)
    checkpoint_every: int = Field(5_000, ge=1)
    reward: RewardConfig = RewardConfig()
    validation: ValidationConfig = ValidationConfig()

    @model_validator(mode="after")
    def _one_env_for_tables(self) -> TrainConfig:
        if self.algorithm == "tabular" and self.envs > 1:
            raise ValueError("envs: tabular Q-learning steps one environment; use 1")
        return self


class RunConfig(Strict):
    scenario: str | None = Field(None, description="the named world applied (stack.sim.scenarios)")
    seed: int = Field(0, ge=0)
    episodes: int = Field(5, ge=1)
    highway: HighwayConfig = HighwayConfig()
    sim: SimConfig = SimConfig()
    control_rate_hz: float = Field(15.0, gt=0)
    decision_period_s: float = Field(1.0, gt=0)
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

    @property
    def dt(self) -> float:
        """One control tick = one physics frame [s]."""
        return 1.0 / self.control_rate_hz

    @property
    def decision_ticks(self) -> int:
        """Control ticks between two decisions."""
        return max(1, round(self.decision_period_s * self.control_rate_hz))


def _one_line(error: ValidationError, source: str) -> str:
    first = error.errors()[0]
    key = ".".join(str(part) for part in first["loc"])
    message = first["msg"].removeprefix("Value error, ")
    if first["type"] == "extra_forbidden":
        message = "unknown key"
    elif first["type"] != "value_error" and not isinstance(first.get("input"), dict):
        message = f"{message} (got {first.get('input')!r})"
    return f"{source}: {key}: {message}" if key else f"{source}: {message}"


def _set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    node = data
    *parents, leaf = dotted.split(".")
    for part in parents:
        node = node.setdefault(part, {})
    node[leaf] = value


def build_config(data: dict[str, Any], source: str = "config", **overrides: Any) -> RunConfig:
    """Validate `data` in its scenario (`scenario` in `overrides` or in `data`, see
    `stack.sim.scenarios`) with dotted-key `overrides` applied (None values are ignored)."""
    data = dict(data)
    scenario = overrides.pop("scenario", None) or data.get("scenario")
    if scenario is not None:
        if not isinstance(scenario, str):
            raise ConfigError(
                f"{source}: scenario: expected a scenario name, one of {', '.join(scenarios.names())}"
            )
        try:
            data = scenarios.apply(scenario, data)
        except ValueError as error:
            raise ConfigError(f"{source}: scenario: {error}") from None
    for dotted, value in overrides.items():
        if value is not None:
            _set_dotted(data, dotted.replace("__", "."), value)
    try:
        return RunConfig.model_validate(data)
    except ValidationError as error:
        raise ConfigError(_one_line(error, source)) from None


def load_config(path: Path | str, **overrides: Any) -> RunConfig:
    """Read a YAML run config, apply CLI overrides, validate; raise ConfigError on any problem."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such config file")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of keys at the top level")
    return build_config(data, str(path), **overrides)
