"""The batched decision MDP in the ecosystem's shapes: `make_vec`'s vector entry point gives what
gymnasium's SyncVectorEnv of the per-world env gives, step for step across its autoresets; the SB3
VecEnv gives what SB3's DummyVecEnv of the per-world env gives; SB3's DQN learns on it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import DQN
from stable_baselines3.common.vec_env import DummyVecEnv

import stack  # noqa: F401 - registers the envs
from stack.settings.run import build_config, training_worlds
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.gym_vector_env import DecisionVecEnv, HierarchicalHighwayVectorEnv

SHORT = {"highway": {"duration": 6}}
"""Episodes of 6 s: several end, and are reset, within a few decisions."""
ID = "drivestack/HierarchicalHighway-v0"
COMPARED_INFO = ("crashed", "speed", "lane_changes", "masked", "aborted")


def test_make_vec_vector_entry_point_is_the_sync_vector_env_of_the_per_world_env():
    kwargs = {"num_envs": 3, "config": SHORT}
    batched = gym.make_vec(ID, vectorization_mode="vector_entry_point", **kwargs)
    synced = gym.make_vec(ID, vectorization_mode="sync", **kwargs)
    assert isinstance(batched, HierarchicalHighwayVectorEnv)
    assert batched.single_observation_space == synced.single_observation_space
    found, expected = batched.reset(seed=5), synced.reset(seed=5)
    np.testing.assert_array_equal(found[0], expected[0])
    rng, ends = np.random.default_rng(0), 0
    for _ in range(16):
        actions = rng.integers(0, 3, 3)
        found, expected = batched.step(actions), synced.step(actions)
        for mine, theirs in zip(found[:4], expected[:4], strict=True):
            np.testing.assert_array_equal(mine, theirs)
        for key in COMPARED_INFO:
            np.testing.assert_array_equal(found[4][key], expected[4][key], err_msg=key)
        ends += int((found[2] | found[3]).sum())
    assert ends >= 3
    batched.close()
    synced.close()


MIX = {
    "perception": {"lanes": "ego", "lane_code": "sides"},
    "train": {"scenarios": {"dense": 1.0, "lanes-3": 1.0, "random": 1.0}},
}
"""A training mix: each world's generator draws its member, then its traffic seed."""


@pytest.mark.parametrize(
    ("data", "worlds", "steps", "least_ends"),
    [(SHORT, 2, 14, 2), (MIX, 3, 5, 0), pytest.param(MIX, 3, 50, 3, marks=pytest.mark.slow)],
)
def test_the_sb3_vec_env_is_dummy_vec_env_of_the_per_world_env(data, worlds, steps, least_ends):
    config = build_config(data, "test")
    mine = DecisionVecEnv(config, worlds, seed=7)
    theirs = DummyVecEnv([lambda: HierarchicalHighwayEnv(config)] * worlds)
    theirs.seed(7)
    np.testing.assert_array_equal(mine.reset(), theirs.reset())
    drawn = [env.world_name for env in theirs.envs]  # type: ignore[attr-defined]
    names = list(training_worlds(config))
    assert [names[k] for k in mine.worlds.members] == drawn
    rng, ends = np.random.default_rng(1), 0
    for _ in range(steps):
        actions = rng.integers(0, 3, worlds)
        mine.step_async(actions)
        theirs.step_async(actions)
        found, expected = mine.step_wait(), theirs.step_wait()
        for a, b in zip(found[:3], expected[:3], strict=True):
            np.testing.assert_array_equal(a, b)
        for info, other in zip(found[3], expected[3], strict=True):
            assert ("terminal_observation" in info) == ("terminal_observation" in other)
            if "terminal_observation" in info:
                ends += 1
                np.testing.assert_array_equal(info["terminal_observation"], other["terminal_observation"])
                assert info["TimeLimit.truncated"] == other["TimeLimit.truncated"]
    assert ends >= least_ends
    assert [names[k] for k in mine.worlds.members] == [env.world_name for env in theirs.envs]  # type: ignore[attr-defined]
    mine.close()
    theirs.close()


def test_sb3_dqn_learns_on_the_batched_vec_env():
    env = DecisionVecEnv({"highway": {"duration": 4}}, 4, seed=0)
    model = DQN("MlpPolicy", env, learning_starts=16, buffer_size=1_000, batch_size=16, seed=0, device="cpu")
    model.learn(total_timesteps=96)
    assert model.num_timesteps >= 96
    buffer = model.replay_buffer
    stored = buffer.buffer_size if buffer.full else buffer.pos
    assert stored * env.num_envs >= 96
    assert buffer.dones[:stored].any()
    assert model.predict(env.reset(), deterministic=True)[0].shape == (4,)
    env.close()


def test_make_vec_names_the_way_out_for_a_config_the_batch_refuses():
    with pytest.raises(ValueError, match="PID tracker.*vectorization_mode='sync'"):
        gym.make_vec(ID, num_envs=2, config={"controller": {"type": "mpc"}})
