"""Learning from an expert's demonstrations (DQfD): n-step returns of recorded episodes, the
large-margin loss, pre-training that makes the greedy policy the expert's, recording in the decision
MDP, and the config and checkpoint checks."""

import json
import signal

import gymnasium as gym
import numpy as np
import pytest
import torch as th
import yaml

from perception.grid import OccupancyGridBuilder
from planner.agents import decide
from planner.ddqn import Demonstrations, DoubleDQN, margin_loss
from planner.mobil import MobilAgent
from stack.runtime.executors import completed
from stack.settings.run import build_config, grid_config
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.demonstrations import (
    batch_experts,
    batched_expert_episodes,
    collect_demonstrations,
    demonstration_worlds,
    expert_episode,
    expert_policy,
)
from stack.training.summary import DemonstrationsUsed
from stack.training.trainer import Trainer
from tests.test_train import TINY


def test_an_episode_s_n_step_returns_stop_at_its_end():
    observations = np.arange(4, dtype=np.float32).reshape(4, 1)
    demonstrations = Demonstrations.from_episode(
        observations, np.array([0, 1, 2]), np.array([1.0, 2.0, 3.0]), True, gamma=0.5, n_steps=2
    )
    np.testing.assert_allclose(demonstrations.rewards, [1 + 0.5 * 2, 2 + 0.5 * 3, 3])
    np.testing.assert_array_equal(demonstrations.next_observations.ravel(), [2, 3, 3])
    assert demonstrations.dones.tolist() == [0, 1, 1], "the crash is within reach of the last two"
    np.testing.assert_allclose(demonstrations.discounts, [0.25, 0.25, 0.5])
    timed_out = Demonstrations.from_episode(observations, np.array([0, 1, 2]), np.ones(3), False, 0.5, 2)
    assert not timed_out.dones.any(), "a time limit bootstraps from the last observation"


def test_the_margin_loss_is_zero_once_the_expert_s_action_leads_by_the_margin():
    q_values = th.tensor([[1.5, 2.0, 0.0], [1.0, 2.0, 0.0], [3.0, 2.0, 0.0]])
    expert = th.tensor([[1], [0], [0]])
    per_row = [margin_loss(q_values[i : i + 1], expert[i : i + 1], 0.8).item() for i in range(3)]
    np.testing.assert_allclose(per_row, [0.3, 1.8, 0.0], atol=1e-6), "leads by 0.5, trails by 1, leads by 1"
    np.testing.assert_allclose(margin_loss(q_values, expert, 0.8).item(), np.mean(per_row), atol=1e-6)


class Bandit(gym.Env):
    """One-step episodes with a 3-value observation; the model only needs its spaces."""

    observation_space, action_space = gym.spaces.Box(-1, 1, (3,)), gym.spaces.Discrete(3)

    def reset(self, *, seed=None, options=None):
        return np.zeros(3, np.float32), {}

    def step(self, action):
        return np.zeros(3, np.float32), 0.0, True, False, {}


def test_pretraining_makes_the_greedy_policy_the_expert_s():
    """An expert picks the largest of three values; rewards say nothing (all zero), so only the
    margin loss can teach its choice: after pre-training the greedy policy agrees on new states."""
    rng = np.random.default_rng(0)
    states = rng.uniform(-1, 1, (512, 3)).astype(np.float32)
    experts = states.argmax(axis=1)
    parts = [
        Demonstrations.from_episode(np.stack([s, s]), np.array([a]), np.zeros(1), True, 0.9, 1)
        for s, a in zip(states, experts, strict=True)
    ]
    model = DoubleDQN("MlpPolicy", Bandit(), learning_rate=3e-3, seed=0, policy_kwargs={"net_arch": [32]})
    model.demonstrations = Demonstrations.concatenate(parts)
    new_states = rng.uniform(-1, 1, (256, 3)).astype(np.float32)
    before = (model.predict(new_states, deterministic=True)[0] == new_states.argmax(axis=1)).mean()
    np.random.seed(0)
    model.pretrain(1500, 64)
    after = (model.predict(new_states, deterministic=True)[0] == new_states.argmax(axis=1)).mean()
    assert before < 0.6 and after > 0.9, (before, after)
    target, online = model.q_net_target.state_dict(), model.q_net.state_dict()
    assert all(th.equal(target[k], online[k]) for k in online), "the target copies the pre-trained net"


def test_recorded_demonstrations_are_the_expert_s_decisions_on_the_learner_s_observations():
    config = build_config(TINY)
    episode = expert_episode(config, "mobil", 200_000)
    env = HierarchicalHighwayEnv(config)
    observation, _ = env.reset(seed=200_000)
    mobil, expert = MobilAgent(grid_config(config)), expert_policy(env.loop.config, "mobil")
    for step, action in enumerate(episode.actions):
        np.testing.assert_array_equal(episode.observations[step], observation)
        assert action == expert(env.loop) == decide(mobil, mobil_view(env, mobil)).value
        observation, *_ = env.step(action)
    np.testing.assert_array_equal(episode.next_observations[-1], observation)
    assert len(episode) == 5, "TINY's 5 s episodes hold five 1 s decisions"


def mobil_view(env, mobil):
    return OccupancyGridBuilder(mobil.grid_config).build(env.loop.perceived).encode("observation")


@pytest.mark.slow
def test_demonstrations_do_not_depend_on_the_number_of_processes():
    data = {**TINY, "train": {**TINY["train"], "demonstrations": {"episodes": 3}}}
    one = collect_demonstrations(build_config(data), progress=False)
    two = collect_demonstrations(build_config({**data, "train": {**data["train"], "envs": 2}}), False)
    for name, values in one.arrays().items():
        np.testing.assert_array_equal(two.arrays()[name], values, err_msg=name)


@pytest.mark.parametrize(
    ("demonstrations", "masked"),
    [
        ({"expert": "lookahead"}, False),
        (
            {
                "expert": "lookahead",
                "experts": {"jam": "mobil"},
                "scenarios": {"jam": 1.0, "overtaking": 1.0},
            },
            True,
        ),
    ],
)
def test_demonstrations_on_batched_worlds_are_the_episodes_recorded_one_world_at_a_time(
    demonstrations, masked
):
    data = {**TINY, "highway": {**TINY["highway"], "duration": 8}}
    data["train"] = {**TINY["train"], "action_mask": masked, "demonstrations": demonstrations}
    config = build_config(data)
    world, settings = demonstration_worlds(config), config.train.demonstrations
    seeds = [200_020, 200_021, 200_022, 200_023]
    batched = batched_expert_episodes(world, settings, seeds)
    assert batched is not None
    for seed, episode in zip(seeds, batched, strict=True):
        alone = expert_episode(world, settings, seed)
        for name, values in alone.arrays().items():
            np.testing.assert_array_equal(episode.arrays()[name], values, err_msg=f"{seed} {name}")
    assert any(len(set(episode.actions.tolist())) > 1 for episode in batched), "some lane change taught"


def test_an_oracle_expert_records_one_world_at_a_time():
    data = {**TINY, "train": {**TINY["train"], "demonstrations": {"expert": "oracle"}}}
    config = build_config(data)
    assert batch_experts(demonstration_worlds(config), config.train.demonstrations) is None


def test_a_run_with_demonstrations_validates_its_pretrained_model_first(tmp_path):
    data = {**TINY, "train": {**TINY["train"], "demonstrations": {"episodes": 2, "pretrain_steps": 30}}}
    trainer = Trainer(build_config(data), tmp_path, progress=False)
    summary = trainer.run()
    assert [v.step for v in trainer.validation.history][:2] == [0, 10]
    assert trainer.validation.history[0].period == "long"
    assert summary.demonstrations == DemonstrationsUsed(expert="mobil", episodes=2, transitions=10)
    assert len(trainer.model.demonstrations) == 10


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"algorithm": "dqn"}, "demonstrations: only the ddqn algorithm learns from them"),
        (
            {"demonstrations": {"expert": "tabular"}},
            "unknown expert 'tabular'; available: mobil, rule, lookahead, oracle, ddqn, dqn",
        ),
        ({"demonstrations": {"share": 1.0}}, "share"),
    ],
)
def test_bad_demonstration_settings_are_refused_in_one_line(change, message):
    with pytest.raises(ValueError, match=message):
        build_config({**TINY, "train": {**TINY["train"], "demonstrations": {}, **change}})


def test_a_checkpoint_s_demonstrations_are_checked_before_use():
    good = Demonstrations.from_episode(np.zeros((3, 4)), np.array([0, 2]), np.ones(2), False, 0.9, 1)
    assert len(Demonstrations.from_arrays(good.arrays(), 4, 3)) == 2
    for change, field in (
        ({"actions": np.array([0, 3])}, "actions"),
        ({"actions": np.array([0.0, 0.5])}, "actions"),
        ({"rewards": np.array([1.0, np.nan], np.float32)}, "rewards"),
        ({"observations": np.zeros((2, 5), np.float32)}, "observations"),
    ):
        with pytest.raises(ValueError, match=field):
            Demonstrations.from_arrays(good.arrays() | change, 4, 3)
    with pytest.raises(ValueError, match="expected"):
        Demonstrations.from_arrays({"actions": np.zeros(2)}, 4, 3)


@pytest.mark.parametrize("expert", ["rule", "lookahead", "oracle", "ddqn", "dqn"])
def test_every_expert_drives_a_recorded_episode(expert):
    """A learned expert sees its own grid (with the permitted commands, for the masked shipped ddqn)."""
    config = build_config(TINY)
    episode = expert_episode(config, expert, 200_001)
    assert len(episode) == 5 and set(episode.actions) <= {0, 1, 2}
    assert episode.observations.shape[1] == HierarchicalHighwayEnv(config).observation_space.shape[0]


def test_with_an_action_mask_an_expert_s_refused_command_is_recorded_as_stay():
    """The rule agent proposes changes the loop would not carry out in a jam (5 in this episode);
    masked, every recorded action is one the observation permits, and the episode is the one the
    loop drove."""
    masked = {**TINY, "scenario": "jam", "highway": {"duration": 15}}
    masked["train"] = {**TINY["train"], "action_mask": True}
    config = build_config(masked)
    episode = expert_episode(config, "rule", 200_003)
    permitted = episode.observations[:, -3:]
    assert all(permitted[step, action] == 1 for step, action in enumerate(episode.actions))
    env = HierarchicalHighwayEnv(config)
    observation, _ = env.reset(seed=200_003)
    rule, refused = expert_policy(env.loop.config, "rule"), 0
    for action in episode.actions:
        refused += rule(env.loop) != action
        observation, *_ = env.step(action)
    assert env.loop.safety.masked == 0 and refused > 0
    np.testing.assert_array_equal(episode.next_observations[-1], observation)


def deaf_after_an_expert_episode(seed):
    """Whether Ctrl-C is ignored once an expert episode ran here."""
    expert_episode(build_config(TINY), "mobil", seed)
    return signal.getsignal(signal.SIGINT) == signal.SIG_IGN


def test_recording_workers_leave_ctrl_c_to_the_learner():
    """Ctrl-C reaches every process of the terminal's group: the recording workers ignore it (a
    worker that died would break the pool), the learner stops the run with a checkpoint."""
    assert [deaf for _, deaf in completed(deaf_after_an_expert_episode, [1, 2], jobs=2)] == [True, True]
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)  # a background job ignores it
    try:
        assert not deaf_after_an_expert_episode(3), "in the learner's own process Ctrl-C still stops the run"
    finally:
        signal.signal(signal.SIGINT, inherited)


def test_demonstrations_come_from_their_own_worlds_when_named():
    """`demonstrations.scenarios` is the mix the expert drives (the learner's own mix otherwise):
    MOBIL demonstrated in a jam starts at a jam's speed, not at highway-v0's 25 m/s."""
    demonstrations = {"episodes": 2, "scenarios": {"jam": 1.0}}
    config = build_config({**TINY, "train": {**TINY["train"], "demonstrations": demonstrations}})
    assert config.train.scenarios == {}
    world = demonstration_worlds(config)
    env = HierarchicalHighwayEnv(world)
    assert world.train.scenarios == {"jam": 1.0} and env.world_names == ["jam"]
    env.close()
    lane_code_and_speed = 3  # the observation ends with the ego's speed, then the lane code's 2 bits
    speed_column = (
        OccupancyGridBuilder(grid_config(config)).observation_space(3).shape[0] - lane_code_and_speed
    )
    recorded = collect_demonstrations(config, progress=False).observations[:, speed_column]
    highway = expert_episode(config, "mobil", 200_001).observations[:, speed_column]
    assert recorded.max() < 0.5 < highway[0], "ego speed / MAX_SPEED: a jam's crawl, highway-v0's 25 m/s"


@pytest.mark.parametrize(
    ("mix", "message"),
    [
        ({"nowhere": 1.0}, "unknown scenario 'nowhere'"),
        ({"lanes-3": 1.0, "lanes-5": 1.0}, "train.demonstrations.scenarios: the observation encoding"),
        ({"lanes-5": 1.0}, "lanes-5 and the configured road"),
    ],
)
def test_demonstration_worlds_are_checked_as_the_training_mix_is(mix, message):
    demonstrations = {"scenarios": mix}
    with pytest.raises(ValueError, match=message):
        build_config({**TINY, "train": {**TINY["train"], "demonstrations": demonstrations}})


def test_a_run_s_own_road_is_checked_even_when_its_scenario_is_demonstrated():
    """The run's road (`lanes-3` made 5 lanes wide) is not the demonstrated `lanes-3`."""
    data = {**TINY, "train": {**TINY["train"], "demonstrations": {"scenarios": {"lanes-3": 1.0}}}}
    with pytest.raises(ValueError, match=r"lanes-3 and lanes-3 \(the run's road\) \(lane counts \[3, 5\]\)"):
        build_config(data, scenario="lanes-3", highway__lanes_count=5)


def _taught(demonstrations: dict, **highway) -> dict:
    """TINY learning from `demonstrations` (on a road with `highway`'s keys changed)."""
    return {
        **TINY,
        "highway": {**TINY["highway"], **highway},
        "train": {**TINY["train"], "demonstrations": demonstrations},
    }


def test_each_world_is_demonstrated_by_the_expert_named_for_it():
    """`experts` gives some worlds a teacher of their own (the one worth copying there): an episode
    drawn in a jam is the rule agent's, one drawn on highway-v0 MOBIL's, action for action."""
    demonstrations = {
        "expert": "mobil",
        "experts": {"jam": "rule"},
        "scenarios": {"jam": 1.0, "highway-v0": 1.0},
    }
    config = build_config(_taught(demonstrations, duration=15))
    world, settings = demonstration_worlds(config), config.train.demonstrations
    drawn, differs = set(), False
    for seed in (200_015, 200_016, 200_018):  # highway-v0, then two jams (the second's rule is not MOBIL's)
        env = HierarchicalHighwayEnv(world)
        env.reset(seed=seed)
        scenario = env.loop.config.scenario
        env.close()
        drawn.add(scenario)
        own = {"jam": "rule", "highway-v0": "mobil"}[scenario]
        taught = expert_episode(world, settings, seed).actions
        np.testing.assert_array_equal(taught, expert_episode(world, own, seed).actions)
        if scenario == "jam":
            differs |= not np.array_equal(taught, expert_episode(world, "mobil", seed).actions)
    assert drawn == {"jam", "highway-v0"} and differs, (
        "both worlds drawn; in a jam the rule agent is not MOBIL"
    )


def test_a_learned_expert_decides_with_the_model_file_named():
    """A Q-network teaches with `expert_model` (by default its shipped file): the shipped DQN named
    by path demonstrates what the shipped DQN does; a DDQN named with the DQN's file is refused
    before any episode, in one line, as is a model file for no learned expert."""
    from planner.factory import model_path
    from planner.model_file import ModelFileError
    from stack.runs.model_fit import checked_expert_model

    shipped = model_path("dqn", None)
    named = build_config(_taught({"expert": "dqn", "expert_model": str(shipped)}))
    default = build_config(_taught({"expert": "dqn"}))
    assert checked_expert_model(named) == shipped == checked_expert_model(default)
    episode = expert_episode(named, named.train.demonstrations, 200_001)
    np.testing.assert_array_equal(episode.actions, expert_episode(default, "dqn", 200_001).actions)
    wrong = build_config(_taught({"expert": "ddqn", "expert_model": str(shipped)}))
    with pytest.raises(ModelFileError, match="dqn.npz"):
        checked_expert_model(wrong)
    assert checked_expert_model(build_config(_taught({"expert": "lookahead"}))) is None


@pytest.mark.parametrize(
    ("demonstrations", "message"),
    [
        ({"experts": {"jams": "rule"}}, "experts: unknown scenario 'jams'"),
        ({"experts": {"jam": "driver"}}, "experts"),
        ({"expert": "rule", "expert_model": "planner/models/dqn.npz"}, "expert_model: no learned expert"),
        ({"expert": "dqn", "expert_model": "nowhere.npz"}, "no such model file nowhere.npz"),
        ({"expert": "dqn", "experts": {"jam": "ddqn"}}, "at most one learned expert"),
    ],
)
def test_experts_are_checked_with_the_config(demonstrations, message):
    with pytest.raises(ValueError, match=message):
        build_config(_taught(demonstrations))


def test_a_config_names_its_expert_model_beside_it(tmp_path, monkeypatch):
    from stack.settings.run import load_config

    folder = tmp_path / "configs"
    folder.mkdir()
    (folder / "teacher.npz").write_bytes(b"")
    taught = {"demonstrations": {"expert": "ddqn", "expert_model": "teacher.npz"}}
    (folder / "train.yaml").write_text(yaml.safe_dump({"train": taught}))
    monkeypatch.chdir(tmp_path)
    assert load_config("configs/train.yaml").train.demonstrations.expert_model == str(folder / "teacher.npz")


def test_summary_json_keeps_the_teachers_of_each_world():
    """summary.json names every teacher: the default expert, those of some worlds and the file a
    learned one decided with; an older summary without them reads back with none."""
    from stack.training.summary import TrainSummary

    teachers = {"experts": {"jam": "ddqn"}, "expert_model": "/t/teacher.npz"}
    used = DemonstrationsUsed(expert="lookahead", episodes=6, transitions=240, **teachers)
    summary = TrainSummary(
        algorithm="ddqn", network="lanes", target_steps=10, steps=10, wall_time_s=1.0, interrupted=False,
        demonstrations=used, best_validation=None, validations=0, best_model=None, training_curve="-",
    )  # fmt: skip
    written = json.loads(json.dumps(summary.to_json()))
    assert TrainSummary.from_json(written).demonstrations == used
    older_record = {"expert": "mobil", "episodes": 2, "transitions": 10}
    older = {**written, "demonstrations": {**older_record, "scenarios": []}}
    assert TrainSummary.from_json(older).demonstrations == DemonstrationsUsed(**older_record)
