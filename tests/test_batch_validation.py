"""Validation on batched worlds: the same score, bit for bit, as the episodes played one world at a
time, and what a training run keeps with it."""

import json

import numpy as np

from planner.validation import validate
from stack.settings.run import build_config
from stack.training.batch_validation import BatchedValidation
from stack.training.decision_env import HierarchicalHighwayEnv
from tests.test_train import TINY

MIX = {
    **TINY,
    "highway": {"vehicles_count": 12, "duration": 8},
    "perception": {**TINY["perception"], "lane_code": "sides"},
    "train": {
        **TINY["train"],
        "action_mask": True,
        "scenarios": {"lanes-3": 1.0, "incident": 1.0, "random": 1.0},
    },
}


def greedy_on(weights: np.ndarray):
    """A fixed linear policy: changes lane where the observation says so, so worlds differ."""

    def predict(observation, deterministic=True):
        assert observation.ndim == 1, "each world decides on its own observation"
        return int(np.argmax(weights @ observation)), None

    return predict


def test_batched_validation_scores_the_episodes_of_one_world_at_a_time_bit_for_bit():
    config = build_config(MIX)
    env = HierarchicalHighwayEnv(config)
    weights = np.random.default_rng(0).normal(size=(3, env.observation_space.shape[0]))
    predict = greedy_on(weights)
    batched = BatchedValidation.of(config)
    assert batched is not None
    one_at_a_time = validate(predict, env, 5, seed=5)
    for most in (64, 2):
        batched.most = most
        assert batched.measure(predict, 5, 5) == one_at_a_time
    assert len(one_at_a_time.worlds) >= 2, "a mix, scored per world"
    batched.close()


def test_a_run_on_batched_worlds_validates_on_them_and_keeps_what_one_world_at_a_time_kept(
    tmp_path, monkeypatch
):
    """The same run validated both ways: the same validations (every score, bit for bit), the same
    kept model and the same final model, byte for byte."""
    from stack.training import trainer as trainer_module
    from stack.training.trainer import Trainer

    train = {**MIX["train"], "worlds": 4, "target_update_interval": 8, "steps": 40}
    train["validation"] = {"short_every": 20, "short_episodes": 2, "long_every": 40, "long_episodes": 3}
    train["demonstrations"] = {"expert": "mobil", "episodes": 2, "pretrain_steps": 5}
    config = build_config({**MIX, "train": train})
    batched = Trainer(config, tmp_path / "batched", progress=False)
    assert batched.batched_validation is not None
    batched.run()
    monkeypatch.setattr(trainer_module.BatchedValidation, "of", classmethod(lambda cls, config: None))
    Trainer(config, tmp_path / "one-at-a-time", progress=False).run()
    history = [(tmp_path / run / "validation.json").read_text() for run in ("batched", "one-at-a-time")]
    assert history[0] == history[1]
    assert len(json.loads(history[0])) >= 3
    for name in ("best.npz", "final.npz"):
        assert (tmp_path / "batched" / name).read_bytes() == (tmp_path / "one-at-a-time" / name).read_bytes()
