"""What builds the agent of an episode, and what a process keeps between episodes: the env of a
config's road and the learned agents of unchanged model files (`KEPT_PER_PROCESS` each)."""

from __future__ import annotations

import math
import sys
from collections import OrderedDict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from planner.agents import Agent, sees_permitted
from planner.factory import make_agent, model_path
from records import LEARNED_AGENTS
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import grid_config
from stack.runs.model_fit import check_road_fit
from stack.settings.run import RunConfig
from stack.sim.highway import HighwayAdapter

if TYPE_CHECKING:
    from planner.lookahead import LookaheadSetup


def build_agent(config: RunConfig, seed: int) -> Agent:
    """The agent `config.planner` names, for the run's road and grid; raises ValueError (one line)
    for a missing, unsafe or mismatched model file."""
    planner, lanes = config.planner, config.highway.lanes_count
    if planner.agent == "oracle":
        return Oracle.for_road(planner.oracle, lanes, grid_config(config))
    path = model_path(planner.agent, planner.model)
    setup = lookahead_setup(config) if planner.agent == "lookahead" else None
    agent = make_agent(
        planner.agent, lanes, grid_config(config), seed, path or planner.model, setup, planner.change_margin
    )
    expected = getattr(agent, "observation_size", None)
    grid = agent.grid_config or grid_config(config)
    if expected is not None:
        counts = config.highway.lane_counts
        check_road_fit(path or "", grid, agent.encoding, expected, counts, permitted=sees_permitted(agent))
    return with_gate(agent, config, seed)


def with_gate(agent: Agent, config: RunConfig, seed: int) -> Agent:
    """`agent` behind the uncertainty gate (`planner.uncertainty.GatedAgent`) when it is an
    ensemble, `planner.fallback` names an agent and a threshold is known (`planner.
    uncertainty_threshold`, else the one calibrated into its model file), by the measure its model
    file names (`planner.uncertainty.gate_measure`); else `agent` itself. An agent is only a
    `planner.learned.LearnedAgent` once that module is imported: a run of another agent does not
    import it (and torch) to find out, ~1.3 CPU-s of every such process's start."""
    learned = sys.modules.get("planner.learned")
    planner = config.planner
    if learned is None or not isinstance(agent, learned.LearnedAgent):
        return agent
    if agent.metadata.members < 2 or planner.fallback == "none":
        return agent
    threshold = planner.uncertainty_threshold
    if threshold is None:
        threshold = agent.metadata.uncertainty_threshold
    if threshold is None:
        return agent
    from planner.uncertainty import GatedAgent, gate_measure

    setup = lookahead_setup(config) if planner.fallback == "lookahead" else None
    lanes = config.highway.lanes_count
    fallback = make_agent(planner.fallback, lanes, grid_config(config), seed, lookahead=setup)
    return GatedAgent(agent, fallback, threshold, planner.fallback, gate_measure(agent.metadata))


def lookahead_setup(config: RunConfig) -> LookaheadSetup:
    """What the lookahead agent takes from `config`: its settings, the maneuver's and the adaptive
    cruise's parameters, the safety layer's gaps."""
    from planner.lookahead import DrivingModel, LookaheadSetup

    control = config.controller
    driving = DrivingModel(
        set_speed=control.set_speed_mps,
        time_gap=control.time_gap_s,
        standstill_gap=control.standstill_gap_m,
        comfort_decel=control.comfort_decel_mps2,
        max_accel=control.pid.max_acceleration,
        kp_speed=control.pid.kp_speed,
        emergency_decel=control.emergency_decel_mps2,
        emergency_ttc=control.emergency_ttc_s,
        lane_change_s=control.lane_change_duration_s,
        max_course=math.radians(control.lane_change_max_course_deg),
        min_change_speed=control.min_lane_change_speed_mps,
    )
    return LookaheadSetup(config.planner.lookahead, driving, config.planner.safety)


KEPT_PER_PROCESS = 4
"""Envs, and agents, a process keeps for the configs it ran last (a sweep's worker runs several)."""
_adapters: OrderedDict[tuple[str, ...], HighwayAdapter] = OrderedDict()
_agents: OrderedDict[tuple[object, ...], Agent] = OrderedDict()


def kept_adapter(config: RunConfig) -> HighwayAdapter:
    """This process's env for `config`'s road, backend and plant (made on first use)."""
    key = (config.highway.model_dump_json(), config.sim.backend, config.sim.plant)
    adapter = _adapters.get(key)
    if adapter is None:
        adapter = HighwayAdapter(config.highway, config.sim.backend, plant=config.sim.plant)
        _keep(_adapters, key, adapter).close()
    _adapters.move_to_end(key)
    return adapter


def kept_agent(config: RunConfig, seed: int) -> Agent:
    """`build_agent(config, seed)`; a learned agent (or an oracle over one) comes from this
    process's cache while its model file is unchanged: the seed does not reach it."""
    planner = config.planner
    learned = planner.agent if planner.agent != "oracle" else planner.oracle.base
    path = model_path(learned, planner.model if planner.agent != "oracle" else None)
    if learned not in LEARNED_AGENTS or path is None:
        return build_agent(config, seed)
    try:
        stat = Path(path).stat()
    except OSError:
        return build_agent(config, seed)
    road = config.model_dump_json(include={"planner", "perception", "highway", "scenario"})
    key = (road, str(path), stat.st_mtime_ns, stat.st_size, stat.st_ino)
    agent = _agents.get(key)
    if agent is None:
        agent = build_agent(config, seed)
        _keep(_agents, key, agent)
    _agents.move_to_end(key)
    return agent


def _keep(kept: OrderedDict, key: Any, value: Any) -> Any:
    """Keep `value` under `key`, at most `KEPT_PER_PROCESS` entries; the one dropped (or a dummy)."""
    kept[key] = value
    if len(kept) > KEPT_PER_PROCESS:
        return kept.popitem(last=False)[1]
    return _Nothing()


class _Nothing:
    def close(self) -> None:
        pass
