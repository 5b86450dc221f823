"""The layers' sections of a run config: `perception` (the grid, the sensor, who sees what) and
`planner` (the agent, its model file, the safety layer, the oracle's search, the lookahead, the
learned agents' hysteresis and uncertainty gate)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator

from common.plugins import AGENT_GROUP, plugin_name
from perception.sensor import SensorConfig
from perception.tracking import TrackerConfig
from planner.lookahead_config import LookaheadConfig
from planner.model_metadata import MAX_CHANGE_MARGIN
from planner.safety import SafetyConfig
from records import AGENT_NAMES, GridConfig
from stack.settings.train import Strict

NOT_GRID = {"sensor", "tracker", "control_on_ground_truth"}
"""The `perception` keys that are not the grid's."""


class PerceptionConfig(GridConfig):
    """The occupancy grid (perception.grid.GridConfig's keys), the sensor model, and who sees it:
    by default the agent, the safety layer and the adaptive cruise all act on the perceived world;
    `control_on_ground_truth` lets safety and cruise read the simulator's truth (an ablation)."""

    sensor: SensorConfig = SensorConfig()
    tracker: TrackerConfig = TrackerConfig()
    control_on_ground_truth: bool = False


class OracleConfig(Strict):
    """The tree's depth (decisions), the look-ahead horizon [s], the lane-change margin [m] and the
    agent that drives after the tree's last decision (`ddqn`: the shipped Double DQN, so the
    search improves on the best agent there is)."""

    depth: int = Field(2, ge=1, le=3)
    horizon_s: float = Field(30.0, gt=0, le=60)
    margin_m: float = Field(0.0, ge=0, le=100, description="lane-change margin [m]")
    base: Literal["keep-lane", "mobil", "rule", "ddqn"] = "ddqn"


class PlannerConfig(Strict):
    """`agent`: a built-in name, a name an installed package registers (entry points
    `drivestack.agents`) or a plug-in class `module.path:Class` / `file.py:Class` (docs/plugins.md)."""

    agent: Annotated[str, plugin_name("agent", AGENT_NAMES, AGENT_GROUP)] = "rule"
    model: Path | None = None
    safety: SafetyConfig = SafetyConfig()
    oracle: OracleConfig = OracleConfig()
    lookahead: LookaheadConfig = LookaheadConfig()
    change_margin: float | None = Field(
        None,
        ge=0,
        le=MAX_CHANGE_MARGIN,
        description="[Q-value] the learned agents' hysteresis: ddqn and dqn change lane only when the "
        "change's Q-value beats STAY's by at least this much; null: the one calibrated into the "
        "model file, else 0",
    )
    fallback: Literal["lookahead", "mobil", "none"] = Field(
        "lookahead", description="who decides where an ensemble's members disagree on its command by "
        "more than uncertainty_threshold (planner.uncertainty); none: no gate",
    )  # fmt: skip
    uncertainty_threshold: float | None = Field(
        None,
        ge=0,
        le=1e6,
        description="the members' disagreement above which the fallback decides, by the measure of "
        "the model file's calibration (planner.uncertainty.gate_measure; advantage_ratio for a file "
        "never calibrated); null: the one calibrated into the model file (drivestack "
        "gate-calibrate), else no gate",
    )

    @field_validator("model")
    @classmethod
    def _absolute_model(cls, model: Path | None) -> Path | None:
        """The file as an absolute path (as plug-in files are): a run's config.yaml names the same
        file from any directory."""
        if model is None:
            return None
        try:
            return model.expanduser().resolve()
        except RuntimeError:
            raise ValueError(f"{str(model)[:120]!r}: no home directory for its '~'") from None
