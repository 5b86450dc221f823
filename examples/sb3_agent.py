"""A stable-baselines3 policy you trained on `drivestack/HierarchicalHighway-v0`, driving as a plug-in
agent (docs/plugins.md).

    .venv/bin/python examples/sb3_agent.py [--steps 20000]   # train, save, drive one episode
    drivestack compare --agents examples/sb3_agent.py:SB3Agent,ddqn --models \\
        examples/sb3_agent.py:SB3Agent=policy.pt --episodes 20

Run as a script it trains SB3's DQN for `--steps` decisions (a tiny budget by default: this shows
the wiring, not a good driver), saves the policy's weights alone (`policy.pt`, tensors only) and
drives one episode through the stack. `SB3Agent` loads those weights with
`torch.load(weights_only=True)`, which never runs code from the file, into a fresh `DQNPolicy`
built for the observation space of the run's road.
"""

import argparse
from pathlib import Path

import gymnasium as gym
import torch
from stable_baselines3 import DQN
from stable_baselines3.dqn.policies import DQNPolicy

from perception.grid import OccupancyGridBuilder

ENCODING = "observation"
"""The encoding the env shows the policy (`train.encoding`, the env's default)."""


class SB3Agent:
    """The greedy action of a DQN policy whose weights (`policy.state_dict()`) are in `model`."""

    encoding = ENCODING
    grid_config = None

    def __init__(self, model: str | None, lanes: int, grid) -> None:
        if model is None:
            raise ValueError("SB3Agent needs its weights: --model policy.pt")
        space = OccupancyGridBuilder(grid).space(ENCODING, lanes)
        self.policy = DQNPolicy(space, gym.spaces.Discrete(3), lr_schedule=lambda _: 0.0)
        self.policy.load_state_dict(torch.load(model, weights_only=True))
        self.policy.set_training_mode(False)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        return self.policy.predict(observation, state, episode_start, deterministic)


def train(steps: int, path: Path, duration: float) -> None:
    """DQN on HierarchicalHighway-v0 for `steps` decisions; the policy's weights saved at `path`."""
    config = {"highway": {"duration": duration}, "train": {"encoding": ENCODING}}
    env = gym.make("drivestack/HierarchicalHighway-v0", config=config)
    model = DQN("MlpPolicy", env, learning_starts=min(steps, 100), buffer_size=10_000, seed=0, verbose=0)
    model.learn(total_timesteps=steps)
    torch.save(model.policy.state_dict(), path)
    env.close()


if __name__ == "__main__":
    import stack

    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=40, help="training decisions")
    parser.add_argument("--out", type=Path, default=Path("policy.pt"))
    args = parser.parse_args()
    train(args.steps, args.out, duration=10)
    config = stack.build_config(
        {
            "planner": {"agent": f"{Path(__file__).resolve()}:SB3Agent", "model": str(args.out)},
            "highway": {"duration": 10},
        }
    )
    result = stack.run_episode(config, episode=0)
    print(f"one 10-s episode: mean speed {result.mean_speed:.1f} m/s, {result.lane_changes} lane changes")
