"""Invalid-action masking (`train.action_mask`): the safety layer's permitted commands end the
observation; the agent acts, explores and bootstraps among them, so it is never taught by a command
the layer refuses, and a model trained so drives with no masked command."""

import csv
import json

import gymnasium as gym
import numpy as np
import torch as th
from typer.testing import CliRunner

from planner.ddqn import DoubleDQN, double_q_target
from planner.learned import LearnedAgent, q_network
from planner.model_file import load_model
from planner.model_metadata import ModelMetadata
from records import Command, GridConfig
from stack.apps.cli import app
from stack.settings.run import build_config
from stack.training.decision_env import HierarchicalHighwayEnv
from tests.test_train import TINY, trained

MASKED = {**TINY, "train": {**TINY["train"], "action_mask": True}}
OBSERVATIONS = np.array([[0.5, 0, 1, 1], [0.5, 1, 1, 1], [0.5, 0, 1, 0]], dtype=np.float32)
"""One grid value, then LEFT / STAY / RIGHT permitted (1) or refused (0)."""


class FourValues(gym.Env):
    """The spaces of a masked observation of one grid value; never stepped."""

    observation_space, action_space = gym.spaces.Box(0, 1, (4,)), gym.spaces.Discrete(3)


def biased(action_mask: bool) -> DoubleDQN:
    """A DoubleDQN whose Q-values are LEFT 3 > STAY 2 > RIGHT 1 for every observation."""
    model = DoubleDQN(
        "MlpPolicy", FourValues(), action_mask=action_mask, policy_kwargs={"net_arch": [8]}, seed=0
    )
    with th.no_grad():
        for parameter in model.q_net.parameters():
            parameter.zero_()
        model.q_net.q_net[-1].bias.copy_(th.tensor([3.0, 2.0, 1.0]))
    return model


def test_the_double_q_target_bootstraps_from_the_best_permitted_command():
    online = th.tensor([[5.0, 1.0, 2.0], [0.0, 3.0, 9.0]])
    target = th.tensor([[10.0, 20.0, 30.0], [40.0, 50.0, 60.0]])
    permitted = th.tensor([[0.0, 1.0, 1.0], [1.0, 1.0, 0.0]])
    rewards, dones = th.ones(2, 1), th.tensor([[0.0], [1.0]])
    masked = double_q_target(rewards, dones, 0.5, online, target, permitted)
    assert masked.reshape(-1).tolist() == [1 + 0.5 * 30.0, 1.0], "RIGHT (online 2 > 1), then done"
    plain = double_q_target(rewards, th.zeros(2, 1), 0.5, online, target)
    assert plain.reshape(-1).tolist() == [1 + 0.5 * 10.0, 1 + 0.5 * 60.0], "without a mask: LEFT, RIGHT"
    undone = double_q_target(rewards, th.zeros(2, 1), 0.5, online, target, permitted)
    assert undone[1].item() == 1 + 0.5 * 50.0, "STAY: the best of LEFT and STAY online"


def test_greedy_and_exploring_actions_keep_to_the_permitted_commands():
    model = biased(action_mask=True)
    greedy, _ = model.predict(OBSERVATIONS, deterministic=True)
    assert greedy.tolist() == [Command.STAY, Command.LEFT, Command.STAY]
    assert biased(action_mask=False).predict(OBSERVATIONS, deterministic=True)[0].tolist() == [0, 0, 0]
    model.exploration_rate = 1.0
    drawn = np.array([model.predict(OBSERVATIONS)[0] for _ in range(300)])
    for row, permitted in enumerate(OBSERVATIONS[:, 1:] > 0.5):
        seen = set(drawn[:, row].tolist())
        assert seen == set(np.flatnonzero(permitted).tolist()), (row, seen)
    single, _ = model.predict(OBSERVATIONS[2])
    assert single.shape == () and int(single) == Command.STAY


class OnlyStay(FourValues):
    """Every observation permits STAY alone; episodes of 5 steps."""

    observed = np.array([0.5, 0, 1, 0], dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.steps = 0
        return self.observed, {}

    def step(self, action):
        self.steps += 1
        return self.observed, 0.0, False, self.steps >= 5, {}


def test_no_rollout_step_of_a_masked_model_takes_a_refused_command():
    """Warm-up (uniform draws before `learning_starts`), exploring and greedy steps alike."""
    model = DoubleDQN(
        "MlpPolicy",
        OnlyStay(),
        action_mask=True,
        learning_starts=30,
        exploration_fraction=0.5,
        policy_kwargs={"net_arch": [8]},
        seed=1,
    )
    model.learn(60)
    stored = model.replay_buffer.actions[: model.replay_buffer.size()].reshape(-1)
    assert len(stored) == 60 and set(stored.tolist()) == {Command.STAY}


def test_a_learned_agent_with_a_mask_decides_among_the_permitted_commands():
    network = q_network(4, 3, [8])
    with th.no_grad():
        for parameter in network.parameters():
            parameter.zero_()
        network[-1].bias.copy_(th.tensor([3.0, 2.0, 1.0]))
    metadata = ModelMetadata(kind="mlp", encoding="observation", observation_size=4, grid=GridConfig())
    masked = LearnedAgent(network, metadata.__class__(**{**metadata.__dict__, "action_mask": True}))
    assert masked.sees_permitted and not LearnedAgent(network, metadata).sees_permitted
    assert masked.choose(OBSERVATIONS).tolist() == [Command.STAY, Command.LEFT, Command.STAY]
    assert masked.scores(OBSERVATIONS[0]).tolist() == [3.0, 2.0, 1.0], "scores stay the network's"


def test_the_observation_ends_with_what_the_loop_would_carry_out():
    """Along an episode: the last three values are `ClosedLoop.permitted` (STAY alone during a
    change); a permitted change is never masked, a refused one is."""
    env = HierarchicalHighwayEnv(build_config({**MASKED, "highway": {"vehicles_count": 20, "duration": 8}}))
    observation, _ = env.reset(seed=3)
    assert env.observation_space.shape == (observation.size,) and env.observation_space.contains(observation)
    seen_changing = refused_tried = False
    for _ in range(20):
        permitted = observation[-3:]
        assert permitted.tolist() == env.loop.permitted().tolist() and permitted[Command.STAY] == 1
        changing = env.loop.maneuver.changing_lane
        seen_changing |= changing
        if changing:
            assert permitted.tolist() == [0, 1, 0]
        masked_before = env.loop.safety.masked
        changes = [c for c in (Command.LEFT, Command.RIGHT) if permitted[c] == 1]
        refused = [c for c in (Command.LEFT, Command.RIGHT) if permitted[c] == 0 and not env.loop.permits(c)]
        if refused and not changing and not refused_tried:
            command, refused_tried = refused[0], True
        else:
            command = changes[0] if changes else Command.STAY
        observation, _, terminated, truncated, _ = env.step(command)
        expected = masked_before + (command in refused and not changing)
        assert env.loop.safety.masked == expected
        if terminated or truncated:
            break
    assert seen_changing and refused_tried
    env.close()


def test_train_with_a_mask_writes_a_model_that_drives_with_no_masked_command(tmp_path):
    config, out = trained(tmp_path, MASKED)
    _, metadata = load_model(out / "best.npz")
    assert metadata["action_mask"] is True
    drive = tmp_path / "drive"
    options = ["--agent", "ddqn", "--model", str(out / "best.npz"), "--episodes", "3", "--no-progress"]
    run = CliRunner().invoke(app, ["run", "-c", str(config), *options, "--out", str(drive)])
    assert run.exit_code == 0, run.output
    with open(drive / "episodes.csv") as episodes:
        rows = list(csv.DictReader(episodes))
    assert len(rows) == 3 and all(row["masked_commands"] == "0" for row in rows)
    assert json.loads((drive / "summary.json").read_text())["episodes"] == 3
