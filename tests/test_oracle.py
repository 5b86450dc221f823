"""The perfect-information oracle: a tree over consecutive decisions on copies of the loop."""

import copy

import numpy as np
import pytest

from records import Command
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import ClosedLoop
from stack.runs.episodes import run
from stack.runs.kept import build_agent
from stack.settings.run import build_config
from stack.sim.highway import HighwayAdapter

SHORT = {"episodes": 1, "seed": 3, "highway": {"duration": 6}, "planner": {"agent": "oracle"}}


@pytest.fixture
def forks(monkeypatch):
    """The oracle's rollouts as forks of the loop, one at a time (not a batch of worlds)."""
    monkeypatch.setattr("stack.agents.oracle.search_refusal", lambda loop, base: "forks asked for")


def test_the_tree_searches_copies_and_leaves_the_loop_untouched(monkeypatch, forks):
    config = build_config(
        {**SHORT, "planner": {"agent": "oracle", "oracle": {"horizon_s": 3}}}, scenario="overtaking"
    )
    oracle = build_agent(config, 0)
    assert isinstance(oracle, Oracle)
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter, grid=oracle.grid_config)
        loop.reset(3)
        loop.perceive()
        before = loop.world
        branches: list[int] = []
        value = Oracle._value

        def counted(self, *args):
            branches.append(args[2])
            return value(self, *args)

        monkeypatch.setattr(Oracle, "_value", counted)
        command = oracle.plan(loop)
        assert loop.world is before and adapter.env.unwrapped.time == before.time, "only copies moved"
    assert command in Command
    assert branches.count(2) == 3, "every root command is tried"
    assert 3 <= branches.count(1) <= 9, "every command after each root that the safety layer lets through"


def test_the_oracle_is_refused_as_an_observation_policy_and_drives_like_any_agent():
    config = build_config({**SHORT, "planner": {"agent": "oracle", "oracle": {"depth": 1, "horizon_s": 2}}})
    with pytest.raises(TypeError, match="plans on copies of the simulator"):
        build_agent(config, 0).predict(np.zeros(3))
    summary = run(config, progress=False).summary
    assert summary["agent"] == "oracle" and summary["collisions"] == 0 and summary["mean_speed"] > 15


def test_oracle_settings_are_validated():
    from stack.settings.run import ConfigError

    for bad, key in [({"depth": 0}, "depth"), ({"horizon_s": -1}, "horizon_s"), ({"base": "oracle"}, "base")]:
        with pytest.raises(ConfigError, match=f"planner.oracle.{key}"):
            build_config({"planner": {"oracle": bad}})


def test_a_command_the_safety_layer_masks_is_refused_before_any_copy(monkeypatch):
    """The ego joins `overtaking` in the rightmost lane: RIGHT leads off the road, so its branch is
    worth nothing without copying the loop; with both changes masked, STAY needs no search."""
    config = build_config(
        {**SHORT, "planner": {"agent": "oracle", "oracle": {"horizon_s": 2}}}, scenario="overtaking"
    )
    oracle = build_agent(config, 0)
    copies: list[object] = []
    real_deepcopy = copy.deepcopy
    monkeypatch.setattr(copy, "deepcopy", lambda *args: copies.append(args[0]) or real_deepcopy(*args))
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter, grid=oracle.grid_config)
        loop.reset(3)
        loop.perceive()
        assert loop.maneuver.lane == 3
        copies.clear()
        assert oracle._value(loop, Command.RIGHT, 2, 0.0, 0.0) == -np.inf and not copies
        monkeypatch.setattr(type(loop.safety), "permits", lambda self, command, *_: command is Command.STAY)
        assert oracle.plan(loop) is Command.STAY and not copies


def test_a_search_that_goes_on_from_the_last_one_rates_every_command_as_a_fresh_search(monkeypatch, forks):
    """The leaves the last search kept, played on for the time the root moved on: every decision's
    values are those of a search that keeps nothing."""
    config = build_config(
        {**SHORT, "highway": {"duration": 8}, "planner": {"agent": "oracle", "oracle": {"horizon_s": 6}}},
        scenario="overtaking",
    )
    keeping, fresh = build_agent(config, 0), build_agent(config, 0)
    assert isinstance(keeping, Oracle) and isinstance(fresh, Oracle)
    continued: list[int] = []
    leaf_value = Oracle._leaf_value

    def counted(self, leaf, *args):
        if self is keeping and len(leaf.commands) > self.config.depth:
            continued.append(len(leaf.commands))
        return leaf_value(self, leaf, *args)

    monkeypatch.setattr(Oracle, "_leaf_value", counted)
    searched = 0
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter, grid=keeping.grid_config)
        loop.reset(3)
        while not loop.done:
            loop.perceive()
            fresh._reached = {}
            command = keeping.plan(loop)
            assert fresh.plan(loop) is command
            assert np.array_equal(keeping.values, fresh.values, equal_nan=True), loop.world.time
            searched += not np.isnan(keeping.values).all()
            loop.act(command)
    assert searched >= 3 and continued, "some searches went on from the last one's leaves"


def _decisions_both_ways(config, seed, monkeypatch):
    """Per decision of one episode: whether the batched search and the forks gave the same command
    and values, and whether the batched search ran."""
    batched, forked = build_agent(config, 0), build_agent(config, 0)
    assert isinstance(batched, Oracle) and isinstance(forked, Oracle)
    batched_values = Oracle._batched_values
    ran: list[bool] = []

    def chosen(self, *args):
        if self is forked:
            return None
        values = batched_values(self, *args)
        ran.append(values is not None)
        return values

    monkeypatch.setattr(Oracle, "_batched_values", chosen)
    same: list[bool] = []
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter, grid=batched.grid_config)
        loop.reset(seed)
        while not loop.done:
            loop.perceive()
            before, time = loop.world, adapter.env.unwrapped.time
            command = batched.plan(loop)
            assert loop.world is before and adapter.env.unwrapped.time == time, "only copies moved"
            same.append(
                forked.plan(loop) is command and np.array_equal(batched.values, forked.values, equal_nan=True)
            )
            loop.act(command)
    return same, ran


def test_the_batched_search_rates_every_command_as_the_forks_do(monkeypatch):
    """Every path of the tree a world of one batch: each decision's values, bit for bit, those of
    the forks played one at a time."""
    config = build_config(
        {**SHORT, "highway": {"duration": 14}, "planner": {"agent": "oracle", "oracle": {"horizon_s": 6}}},
        scenario="overtaking",
    )
    same, ran = _decisions_both_ways(config, 3, monkeypatch)
    assert all(same) and sum(ran) >= 3, (same, ran)


def test_a_loop_seen_through_a_sensor_is_searched_on_forks(monkeypatch):
    config = build_config(
        {**SHORT, "highway": {"duration": 4}, "planner": {"agent": "oracle", "oracle": {"horizon_s": 2}}},
        scenario="noisy",
    )
    same, ran = _decisions_both_ways(config, 3, monkeypatch)
    assert all(same) and not any(ran)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["overtaking", "dense", "incident"])
def test_the_batched_search_decides_as_the_forks_over_whole_episodes(monkeypatch, scenario):
    config = build_config({**SHORT, "highway": {"duration": 40}}, scenario=scenario)
    same, ran = _decisions_both_ways(config, 1014100, monkeypatch)
    assert all(same) and any(ran)
