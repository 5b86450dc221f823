"""Each world of a `DecisionBatch` is the decision MDP (`HierarchicalHighwayEnv`) the `vector`
backend drives alone: every vehicle's s, d, speed and heading, the maneuver's lane and target, the
observation, reward and end flags and the safety layer's and maneuver's counts, at every decision,
bit for bit, across lane changes, masked commands, aborts, emergency braking, crashes and resets,
for any batch size. The configs a batch does not run are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from records.batch import WorldBatch
from stack.batch.closed_loop_batch import ClosedLoopBatch
from stack.settings.run import build_config
from stack.training.decision_batch import DecisionBatch
from stack.training.decision_env import HierarchicalHighwayEnv


def cycling(world: int, decision: int) -> int:
    """Commands that change lane often, differently per world (LEFT, STAY, RIGHT)."""
    return (world * 7 + decision * 3 + decision // 4) % 3


def weaving(world: int, decision: int) -> int:
    """Only lane changes, left and right by turns: masks, aborts and (unguarded) crashes."""
    return (0, 2)[(world + decision) % 2]


def drive_both(data: dict, worlds: int, decisions: int, policy=cycling) -> dict[str, int]:
    """Drive `worlds` per-world envs and one batch of them side by side for `decisions` decisions
    (a world whose episode ends is reset in both with the env's next traffic seed), asserting
    identity at every decision; what happened on the way, summed over the worlds and their
    episodes."""
    config = build_config(data, "test")
    envs = [HierarchicalHighwayEnv(config) for _ in range(worlds)]
    for k, env in enumerate(envs):
        env.reset(seed=k)
    batch = DecisionBatch(config, worlds)
    observations = batch.reset([env.loop.seed for env in envs], [member(env) for env in envs])
    for k, env in enumerate(envs):
        np.testing.assert_array_equal(observations[k], env._observe())
    assert batch.loop.batch is not None
    seen = {"ends": 0, "crashes": 0, "roads": len(set(batch.loop.batch.lanes_count.tolist()))}
    members = {member(env) for env in envs}
    finished_counts = np.zeros(3, dtype=np.int64)
    for decision in range(decisions):
        commands = [policy(k, decision) for k in range(worlds)]
        decided = batch.step(commands)
        ended = []
        for k, env in enumerate(envs):
            observation, reward, terminated, truncated, _ = env.step(commands[k])
            assert_same_world(env, batch, k)
            np.testing.assert_array_equal(decided.observations[k], observation)
            assert (decided.rewards[k], decided.terminated[k], decided.truncated[k]) == (
                reward,
                terminated,
                truncated,
            )
            np.testing.assert_array_equal(decided.permitted[k], env.loop.permitted())
            if terminated or truncated:
                seen["ends"] += 1
                seen["crashes"] += terminated
                env.reset()
                ended.append(k)
        if ended:
            finished_counts += batch.loop.counts[ended].sum(axis=0)
            members |= {member(envs[k]) for k in ended}
            batch.reset_worlds(ended, [envs[k].loop.seed for k in ended], [member(envs[k]) for k in ended])
            observations = batch.observe()
            for k in ended:
                np.testing.assert_array_equal(observations[k], envs[k]._observe())
    counts = batch.loop.counts.sum(axis=0) + finished_counts
    batch.close()
    return seen | {
        "members": len(members),
        "lane_changes": int(counts[0]),
        "masked": int(counts[1]),
        "aborted": int(counts[2]),
        "emergencies": int(batch.loop.flags[:, 1].sum()),
    }


def member(env: HierarchicalHighwayEnv) -> int:
    """The mix member `env`'s episode drew (0 without a mix)."""
    return env.world_names.index(env.world_name)


def assert_same_world(env: HierarchicalHighwayEnv, batch: DecisionBatch, k: int) -> None:
    alone, together = WorldBatch.of([env.loop.world]), batch.loop.batch
    assert together is not None
    n = int(alone.count[0])
    assert together.count[k] == n
    for name in ("s", "d", "speed", "heading", "lane"):
        np.testing.assert_array_equal(getattr(together, name)[k, :n], getattr(alone, name)[0], err_msg=name)
    seen, perceived = WorldBatch.of([env.loop.perceived]), batch.loop.perceived
    assert perceived is not None
    m = int(seen.count[0])
    assert perceived.count[k] == m
    for name in ("s", "d", "speed", "heading", "lane", "length", "width"):
        np.testing.assert_array_equal(getattr(perceived, name)[k, :m], getattr(seen, name)[0], err_msg=name)
    loop, maneuver = batch.loop, env.loop.maneuver
    assert (loop.lane[k], loop.target[k]) == (maneuver.lane, maneuver.target)
    safety = env.loop.safety.counts
    assert tuple(loop.counts[k]) == (maneuver.lane_changes, safety.masked, safety.aborted)
    assert loop.flags[k, 1] == env.loop.emergency.activations
    assert loop.crashed[k] == env.loop.crashed


STAGE_GRID = {
    "lanes": "ego",
    "lateral_reach": 2,
    "lane_code": "sides",
    "features": ["relative_speed", "ttc", "ego_speed", "ego_lateral"],
}
"""The shipped stage configs' grid: the ego's offset and heading error in the lane show a change."""


@pytest.mark.parametrize(
    ("scenario", "worlds", "decisions", "extra"),
    [
        ("highway-v0", 1, 8, {}),
        ("highway-v0", 4, 5, {}),
        ("overtaking", 3, 10, {"highway": {"duration": 6}}),
        ("incident", 3, 8, {}),
        ("noisy", 3, 10, {}),
        ("overtaking", 3, 10, {"perception": STAGE_GRID}),
    ],
)
def test_each_world_of_a_batch_is_the_decision_env_alone(scenario, worlds, decisions, extra):
    seen = drive_both({"scenario": scenario, **extra}, worlds, decisions)
    assert seen["lane_changes"] + seen["masked"] > 0
    if "highway" in extra:
        assert seen["ends"] == worlds


def test_masked_observations_shaped_rewards_and_aborts_stay_identical():
    data = {
        "scenario": "dense",
        "train": {"action_mask": True, "reward": {"speed_weight": 0.5, "lane_change": 0.1}},
    }
    seen = drive_both(data, 3, 12, weaving)
    assert seen["masked"] > 0


RANDOM = {"scenario": "random", "perception": {"lanes": "ego", "lane_code": "sides"}}
"""The random family, on a grid of one size on every road (its own lane and the sides)."""


def test_random_worlds_each_draw_their_road_and_sensor_as_the_env_does():
    seen = drive_both(RANDOM, 3, 6)
    assert seen["roads"] >= 2


@pytest.mark.slow
def test_random_worlds_match_over_whole_episodes():
    data = {**RANDOM, "highway": {"duration": 15}, "train": {"action_mask": True}}
    seen = drive_both(data, 6, 40, weaving)
    assert seen["roads"] >= 3 and seen["ends"] >= 6


MIX = {
    "perception": {"lanes": "ego", "lane_code": "sides"},
    "train": {"scenarios": {"dense": 2.0, "lanes-3": 1.0, "noisy": 1.0, "random": 1.0}},
}
"""A training mix of roads, traffic, lane counts and sensors, each world drawing its member."""


def test_a_mix_with_the_exit_road_is_the_envs_mix():
    """The exit road's worlds (its through lanes as one segment, `stack.sim.batch.through_road`)
    beside the highway's in one batch, decision for decision as the per-world envs."""
    seen = drive_both({**MIX, "train": {"scenarios": {"dense": 1.0, "exit": 1.0}}}, 6, 24, weaving)
    assert seen["members"] == 2 and seen["lane_changes"] > 0


def test_a_mix_draws_each_episode_s_member_as_the_env_does():
    seen = drive_both(MIX, 4, 6)
    assert seen["members"] >= 2


@pytest.mark.slow
def test_a_mix_matches_over_whole_episodes():
    seen = drive_both(MIX, 6, 45, weaving)
    assert seen["ends"] >= 6 and seen["members"] >= 3


POOR_SENSOR = {
    "range_m": 80.0,
    "position_noise_m": 1.5,
    "miss_probability": 0.3,
    "false_positives": 2.0,
    "false_positive_range_m": 40.0,
}
"""A sensor that misses, drifts and imagines often: phantoms ahead brake the ego, gaps flicker."""


@pytest.mark.parametrize("tracker", ["off", "auto"])
def test_a_poor_sensor_seen_through_matches(tracker):
    """Raw detections (`off`: phantoms brake the ego) and the tracker's confirmed tracks alike."""
    perception = {"sensor": POOR_SENSOR, "tracker": {"mode": tracker}}
    data = {"scenario": "dense", "perception": perception, "train": {"action_mask": True}}
    seen = drive_both(data, 3, 10, weaving)
    assert seen["masked"] > 0 and (seen["emergencies"] > 0 or tracker != "off")


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["noisy", "dense"])
def test_sensed_worlds_match_over_whole_episodes(scenario):
    seen = drive_both({"scenario": scenario, "perception": {"sensor": POOR_SENSOR}}, 4, 45, weaving)
    assert seen["ends"] >= 4


@pytest.mark.slow
@pytest.mark.parametrize(
    "scenario", ["highway-v0", "dense", "jam", "lanes-3", "lanes-5", "overtaking", "incident"]
)
def test_every_batched_scenario_matches_over_whole_episodes(scenario):
    seen = drive_both({"scenario": scenario}, 4, 45)
    assert seen["ends"] >= 4


def test_crashes_without_the_safety_layer_match():
    data = {
        "scenario": "incident",
        "planner": {"safety": {"enabled": False}},
        "controller": {"emergency_ttc_s": 0.0},
    }
    seen = drive_both(data, 4, 30, weaving)
    assert seen["crashes"] >= 1


EAGER_SAFETY = {
    "min_gap_m": 2.0,
    "front_time_gap_s": 0.2,
    "rear_time_gap_s": 0.2,
    "min_ttc_s": 1.0,
    "abort_gap_m": 8.0,
    "abort_ttc_s": 4.0,
}
"""A safety layer that lets changes start into gaps it then gives them up in: aborts, and commands
refused while an aborted change returns, in a few decisions (the shipped one aborts rarely)."""


def test_aborts_match():
    data = {"scenario": "overtaking", "planner": {"safety": EAGER_SAFETY}, "train": {"action_mask": True}}
    seen = drive_both(data, 4, 30, weaving)
    assert seen["aborted"] >= 3


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"controller": {"type": "mpc"}}, "PID tracker"),
        ({"controller": {"type": "stanley"}}, "PID tracker"),
        ({"sim": {"plant": "dynamic"}}, "kinematic plant"),
        ({"scenario": "noisy", "perception": {"control_on_ground_truth": True}}, "ground_truth"),
        ({"train": {"encoding": "binary"}}, "encoding"),
        ({"scenario": "random"}, "batched worlds: the observation encoding has a different size"),
    ],
)
def test_what_a_batch_does_not_run_is_refused_in_one_line(data, message):
    with pytest.raises(ValueError, match=message) as refused:
        DecisionBatch(data, 2)
    assert "\n" not in str(refused.value)


def test_acting_in_an_ended_world_is_refused():
    loop = ClosedLoopBatch(build_config({"highway": {"duration": 1}}, "test"), 2)
    loop.reset([1, 2])
    acted = loop.act(np.array([1, 1]), 30)
    assert loop.done.all() and (acted.ticks < 30).all()
    with pytest.raises(ValueError, match="reset them"):
        loop.act(np.array([1, 1]), 15)
    loop.close()
