"""Agents by name: hand-written baselines and learned models behind one protocol."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from common.plugins import AGENT_GROUP, checked_name
from planner.agents import Agent, FreeGapAgent, KeepLaneAgent, RandomAgent
from planner.mobil import MobilAgent
from records import AGENT_NAMES, LEARNED_AGENTS, POLICY_NAMES, GridConfig, unknown_name

if TYPE_CHECKING:
    from planner.lookahead import LookaheadSetup

MODELS = Path(__file__).parent / "models"

SHIPPED_MODELS: dict[str, Path] = {name: MODELS / f"{name}.npz" for name in ("ddqn", "dqn", "tabular")}
"""The model each learned agent loads without --model, trained by
`drivestack train --config configs/train/NAME.yaml` (NAME: ddqn, dqn, tabular)."""

AGENT_DESCRIPTIONS: dict[str, str] = {
    "ddqn": "Double DQN (the paper's best, the default); the shipped model (one for every road and "
    "traffic) unless --model",
    "dqn": "DQN; the shipped small model unless --model",
    "tabular": "tabular Q-learning on the paper's tabular state; the shipped table unless --model",
    "rule": "hand-written: into the adjacent lane with the most free cells ahead when it is clearly freer",
    "mobil": "MOBIL (Kesting et al.): a change when the incentive beats the threshold and it is safe",
    "lookahead": "PDM-Closed for highways: rolls out each permitted command through the stack's own "
    "maneuver and cruise for 8 s, picks by progress, time to collision and comfort",
    "keep-lane": "never changes lane (adaptive cruise only): the baseline of every comparison",
    "random": "a uniformly random command each decision (seeded)",
    "oracle": "perfect information: searches copies of the simulator (slow; each scenario's ceiling)",
}
"""One line per agent name (`drivestack agents`)."""


def make_agent(
    name: str,
    lanes: int,
    grid: GridConfig,
    seed: int = 0,
    model: Path | str | None = None,
    lookahead: LookaheadSetup | None = None,
    change_margin: float | None = None,
) -> Agent:
    """Build the agent `name` for a road of `lanes` lanes seen through `grid`; learned agents load
    `model` (by default the shipped one; a Q-network decides with the hysteresis `change_margin`,
    None: the one its file holds), the lookahead takes the run's `lookahead` setup (by default the
    stack's defaults). Any other name is a plug-in (`planner.plugins`), given `model` if it takes
    one."""
    if (path := model_path(name, model)) is not None:
        from planner.learned import load_agent

        return load_agent(path, expected_algorithms=(name,), change_margin=change_margin)
    if name == "rule":
        return FreeGapAgent(lanes, grid)
    if name == "mobil":
        return MobilAgent(grid)
    if name == "lookahead":
        from planner.lookahead import LookaheadAgent

        return LookaheadAgent(grid, lookahead)
    if name == "keep-lane":
        return KeepLaneAgent()
    if name == "random":
        return RandomAgent(seed)
    if name in AGENT_NAMES:
        raise ValueError(unknown_name("agent", name, POLICY_NAMES))
    checked_name("agent", AGENT_NAMES, AGENT_GROUP, name)
    from planner.plugins import plugin_agent

    return plugin_agent(name, lanes, grid, seed, model)


def model_path(name: str, model: Path | str | None) -> Path | None:
    """The model file the agent `name` loads: `model`, else the shipped one (None for agents
    without a model)."""
    if name not in LEARNED_AGENTS:
        return None
    return Path(model or SHIPPED_MODELS[name])


def model_label(path: Path | None) -> str | None:
    """How a run names the model file it loaded: `shipped/FILE` for a shipped one (the same on
    every machine), else the path as given."""
    if path is None:
        return None
    return f"shipped/{path.name}" if path.parent == MODELS else str(path)
