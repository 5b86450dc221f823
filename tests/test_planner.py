"""Agents behind one protocol, Double DQN's target, the safe model file."""

from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import DQN
from typer.testing import CliRunner

from perception.grid import GridConfig, OccupancyGridBuilder
from planner.agents import decide, sees_permitted
from planner.ddqn import DoubleDQN, double_q_target
from planner.factory import SHIPPED_MODELS, make_agent
from planner.learned import LearnedAgent, export_q_network, load_agent
from planner.mobil import MobilAgent, MobilPrior
from planner.model_file import ModelFileError, load_model, save_model
from planner.model_metadata import ModelMetadata
from records import ENCODINGS, FEATURES, N_ACTIONS, POLICY_NAMES, Command
from stack.apps.cli import app
from tests.helpers import scene

GRID = GridConfig(cells_ahead=9, cells_behind=4)


def observation_for(agent, world):
    return OccupancyGridBuilder(agent.grid_config or GRID).build(world).encode(agent.encoding)


def tiny_dqn(observation_size: int, algorithm=DoubleDQN):
    space = gym.spaces.Box(-1.0, 1.0, (observation_size,), np.float32)

    class Dummy(gym.Env):
        observation_space, action_space = space, gym.spaces.Discrete(3)

        def reset(self, *, seed=None, options=None):
            return np.zeros(observation_size, np.float32), {}

        def step(self, action):
            return np.zeros(observation_size, np.float32), 0.0, True, False, {}

    return algorithm("MlpPolicy", Dummy(), policy_kwargs={"net_arch": [16]}, seed=0, device="cpu")


@pytest.fixture
def model_files(tmp_path):
    """A tiny DDQN, DQN and tabular model file for the learned agents."""
    grid = GRID.model_copy(update={"lanes": "ego", "features": ("relative_speed",)})
    size = OccupancyGridBuilder(grid).observation_space(3).shape[0]
    metadata = ModelMetadata(
        kind="mlp", encoding="observation", observation_size=size, hidden=(16,), grid=grid
    )
    files = {}
    for name, algorithm in (("ddqn", DoubleDQN), ("dqn", DQN)):
        files[name] = export_q_network(
            tiny_dqn(size, algorithm), tmp_path / f"{name}.npz", replace(metadata, algorithm=name)
        )
    table = np.random.default_rng(0).random((3, 9, 9, 9, 3))
    files["tabular"] = save_model(
        tmp_path / "tabular.npz",
        {"q_table": table},
        {"kind": "qtable", "algorithm": "tabular", "grid": GRID.model_dump(mode="json")},
    )
    return files


@pytest.mark.parametrize("name", POLICY_NAMES)
def test_every_agent_answers_the_protocol(name, model_files):
    world = scene(3, (0.0, 1), [(15.0, 4.0), (30.0, 0.0), (-20.0, 8.0)], speed=25.0, other_speed=20.0)
    agent = make_agent(name, 3, GRID, seed=0, model=model_files.get(name))
    observation = observation_for(agent, world)
    action, state = agent.predict(observation, state="carried", deterministic=True)
    assert int(action) in (0, 1, 2)
    assert state == "carried", "a stateless agent hands the recurrent state back unchanged"
    assert agent.encoding in ENCODINGS
    if name != "random":
        assert decide(agent, observation) == Command(int(action)), "greedy decisions are repeatable"


def test_unknown_agent_lists_what_is_available():
    with pytest.raises(
        ValueError, match="unknown agent 'genius'; available: ddqn, dqn, tabular, rule, mobil"
    ):
        make_agent("genius", 3, GRID)


def test_a_model_for_another_algorithm_or_shape_is_refused(model_files):
    with pytest.raises(ModelFileError, match="holds a 'dqn' model; expected ddqn"):
        make_agent("ddqn", 3, GRID, model=model_files["dqn"])
    agent = make_agent("ddqn", 3, GRID, model=model_files["ddqn"])
    with pytest.raises(
        ValueError, match=r"expects observations of \d+ values \(observation encoding of grid"
    ):
        agent.predict(np.zeros(7, np.float32))


def test_rule_agent_overtakes_into_the_freer_lane_only_when_safe():
    agent = make_agent("rule", 3, GRID)
    blocked = scene(3, (0.0, 1), [(15.0, 4.0), (40.0, 8.0)])
    assert decide(agent, observation_for(agent, blocked)) is Command.LEFT
    unsafe_left = scene(3, (0.0, 1), [(15.0, 4.0), (-5.0, 0.0), (40.0, 8.0)])
    assert decide(agent, observation_for(agent, unsafe_left)) is Command.RIGHT
    clear = scene(3, (0.0, 1), [(-15.0, 4.0)])
    assert decide(agent, observation_for(agent, clear)) is Command.STAY


def test_rule_agent_reads_the_side_lanes_code():
    grid = GRID.model_copy(update={"lanes": "ego", "lane_code": "sides"})
    for lanes in (3, 5):
        agent = make_agent("rule", lanes, grid)
        blocked = scene(lanes, (0.0, 1), [(15.0, 4.0), (40.0, 8.0)])
        observation = OccupancyGridBuilder(grid).build(blocked).encode(agent.encoding)
        assert decide(agent, observation) is Command.LEFT


def test_rule_agent_that_sees_no_cell_ahead_keeps_its_lane():
    grid = GRID.model_copy(update={"cells_ahead": 1})
    agent = make_agent("rule", 3, grid)
    blocked = scene(3, (0.0, 1), [(15.0, 4.0), (40.0, 8.0)])
    observation = OccupancyGridBuilder(grid).build(blocked).encode(agent.encoding)
    assert decide(agent, observation) is Command.STAY


def test_mobil_changes_lane_for_a_gain_and_respects_the_new_follower():
    agent = MobilAgent(GRID)
    slow_leader = scene(3, (0.0, 1), [(15.0, 4.0)], speed=25.0, other_speed=15.0)
    assert decide(agent, observation_for(agent, slow_leader)) in (Command.LEFT, Command.RIGHT)
    fast_follower = scene(
        3, (0.0, 1), [(15.0, 4.0), (-10.0, 0.0), (-10.0, 8.0)], speed=25.0, other_speed=15.0
    )
    world = fast_follower
    world.speed[2:] = 35.0
    assert decide(agent, observation_for(agent, world)) is Command.STAY


def test_mobil_prior_cuts_mobils_own_view_out_of_the_networks_observation():
    """MOBIL inside the prior sees bit for bit what the MOBIL agent sees on its own grid."""
    grid = GRID.model_copy(
        update={"lanes": "ego", "lateral_reach": 2, "lane_code": "sides", "features": FEATURES}
    )
    prior = MobilPrior(grid, 0.4)
    for world in (
        scene(4, (0.0, 1), [(15.0, 4.0), (30.0, 0.0), (-20.0, 8.0), (200.0, 12.0)], other_speed=15.0),
        scene(3, (0.0, 0), [(12.0, 0.0), (-6.0, 4.0)]),
    ):
        network_view = OccupancyGridBuilder(grid).build(world).to_observation()
        own_view = observation_for(prior.mobil, world)
        np.testing.assert_array_equal(prior.mobil_observation(network_view), own_view)


def test_mobil_prior_raises_mobils_change_by_its_bonus_and_the_network_keeps_the_last_word():
    """A network rating LEFT 0.3 below STAY: with a 0.4 bonus it follows MOBIL's proposed LEFT,
    with 0.2 it stays; where MOBIL proposes nothing the bonus changes nothing."""
    grid = GRID.model_copy(update={"lanes": "ego", "features": ("relative_speed", "ego_speed")})
    size = OccupancyGridBuilder(grid).observation_space(3).shape[0]
    network = th.nn.Sequential(th.nn.Linear(size, 3))
    with th.no_grad():
        network[0].weight.zero_()
        network[0].bias.copy_(th.tensor([-0.3, 0.0, -1.0]))
    slow_leader = scene(3, (0.0, 1), [(15.0, 4.0), (-30.0, 8.0)], speed=25.0, other_speed=15.0)
    free_road = scene(3, (0.0, 1), speed=25.0)
    mobil = MobilAgent(grid)
    assert decide(mobil, observation_for(mobil, slow_leader)) is Command.LEFT
    for bonus, expected in ((0.4, Command.LEFT), (0.2, Command.STAY), (0.0, Command.STAY)):
        metadata = ModelMetadata(
            kind="mlp", encoding="observation", observation_size=size, grid=grid, mobil_prior=bonus
        )
        agent = LearnedAgent(network, metadata)
        assert decide(agent, observation_for(agent, slow_leader)) is expected, bonus
        assert decide(agent, observation_for(agent, free_road)) is Command.STAY
        batch = np.stack([observation_for(agent, slow_leader), observation_for(agent, free_road)])
        assert agent.choose(batch).tolist() == [expected, Command.STAY]


def test_a_change_margin_holds_near_ties_and_the_run_config_hands_it_to_the_agent():
    """A network rating LEFT 0.5 above STAY changes lane with a margin of 0.5 or less, stays with
    more; the scores stay the network's; `planner.change_margin` reaches the agent the run builds."""
    network = th.nn.Sequential(th.nn.Linear(4, 3))
    with th.no_grad():
        network[0].weight.zero_()
        network[0].bias.copy_(th.tensor([1.5, 1.0, -2.0]))
    metadata = ModelMetadata(kind="mlp", encoding="observation", observation_size=4, grid=GRID)
    observations = np.zeros((2, 4), dtype=np.float32)
    for margin, expected in ((0.0, Command.LEFT), (0.5, Command.LEFT), (0.51, Command.STAY)):
        agent = LearnedAgent(network, metadata, change_margin=margin)
        assert agent.choose(observations).tolist() == [expected] * 2, margin
        assert agent.scores(observations[0]).tolist() == [1.5, 1.0, -2.0]
    from stack.runs.kept import build_agent
    from stack.settings.run import build_config

    built = build_agent(build_config({"planner": {"agent": "ddqn", "change_margin": 0.25}}, "test"), 0)
    assert isinstance(built, LearnedAgent) and built.change_margin == 0.25
    assert make_agent("ddqn", 4, GRID).change_margin == 0.0


def test_double_q_target_uses_the_online_argmax_and_the_target_value():
    rewards, dones = th.tensor([[1.0], [0.0]]), th.tensor([[0.0], [1.0]])
    online = th.tensor([[0.0, 5.0, 1.0], [3.0, 0.0, 0.0]])
    target = th.tensor([[9.0, 2.0, 4.0], [1.0, 1.0, 1.0]])
    double = double_q_target(rewards, dones, 0.5, online, target)
    vanilla = rewards + (1 - dones) * 0.5 * target.max(dim=1, keepdim=True).values
    assert double.tolist() == [[2.0], [0.0]]  # online picks action 1, target values it 2
    assert vanilla.tolist() == [[5.5], [0.0]]  # max over the target net: over-estimates


def test_double_dqn_trains_and_its_weights_round_trip(tmp_path):
    model = tiny_dqn(6)
    model.learning_starts = 0
    model.learn(64)
    path = export_q_network(
        model,
        tmp_path / "m.npz",
        ModelMetadata(
            kind="mlp", algorithm="ddqn", encoding="observation", observation_size=6, hidden=(16,), grid=GRID
        ),
    )
    agent = load_agent(path)
    observations = np.random.default_rng(1).uniform(-1, 1, (20, 6)).astype(np.float32)
    with th.no_grad():
        expected = model.policy.q_net(th.as_tensor(observations)).numpy()
    np.testing.assert_allclose(agent.q_values(observations), expected, rtol=1e-6)


def test_crafted_and_truncated_model_files_are_refused(tmp_path, model_files):
    data = model_files["ddqn"].read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelFileError, match="not a drivestack model file"):
        load_agent(truncated)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, metadata=np.frombuffer(b"{}", np.uint8), payload=np.array([object()], dtype=object))
    with pytest.raises(ModelFileError, match="unexpected member 'payload.npy'"):
        load_agent(pickled)
    np.savez(
        pickled, **{"metadata": np.frombuffer(b"{}", np.uint8), "array/q": np.array([object()], dtype=object)}
    )
    with pytest.raises(ModelFileError, match="holds object values; only numbers are allowed"):
        load_agent(pickled)
    wrong = tmp_path / "wrong.npz"
    save_model(
        wrong,
        {"0.weight": np.zeros((2, 2))},
        {
            "kind": "mlp",
            "algorithm": "ddqn",
            "observation_size": 9,
            "actions": 3,
            "hidden": [4],
            "encoding": "observation",
            "grid": GRID.model_dump(mode="json"),
        },
    )
    with pytest.raises(ModelFileError, match="model arrays do not match its metadata"):
        load_agent(wrong)
    not_json = tmp_path / "not_json.npz"
    np.savez(not_json, metadata=np.frombuffer(b"\xff\xfe", np.uint8))
    with pytest.raises(ModelFileError, match="not valid JSON"):
        load_agent(not_json)
    with pytest.raises(ModelFileError, match="no such model file"):
        load_agent(tmp_path / "absent.npz")


@pytest.mark.parametrize("algorithm", ["dqn", "tabular"])
def test_every_learned_agent_ships_a_small_model(algorithm):
    agent = make_agent(algorithm, 4, GRID)
    assert agent.metadata.algorithm == algorithm
    assert SHIPPED_MODELS[algorithm].stat().st_size <= 2_000_000


def test_shipped_default_model_loads_safely():
    agent = load_agent(SHIPPED_MODELS["ddqn"], expected_algorithms=("ddqn",))
    assert agent.metadata.algorithm == "ddqn"
    assert SHIPPED_MODELS["ddqn"].stat().st_size <= 2_000_000
    assert agent.metadata.actions == N_ACTIONS
    world = scene(4, (0.0, 1), [(15.0, 4.0), (30.0, 0.0)])
    grid = OccupancyGridBuilder(agent.grid_config).build(world).encode(agent.encoding)
    assert sees_permitted(agent), "it decides among the commands the safety layer permits"
    observation = np.concatenate([grid, np.ones(N_ACTIONS, np.float32)])
    assert observation.size == agent.metadata.observation_size, "it reads the grid it declares"
    assert decide(agent, observation) in tuple(Command)
    for only in Command:
        permitted = np.zeros(N_ACTIONS, np.float32)
        permitted[only] = 1.0
        assert decide(agent, np.concatenate([grid, permitted])) is only, "a refused command is never chosen"


def test_export_writes_an_sb3_zip_that_dqn_load_opens_and_drives_alike(tmp_path):
    """A lane network of the shipped ensemble (its first member, as one model file)."""
    arrays, metadata = load_model(SHIPPED_MODELS["ddqn"])
    first = "member0."
    member = save_model(
        tmp_path / "member.npz",
        {name.removeprefix(first): array for name, array in arrays.items() if name.startswith(first)},
        {key: value for key, value in metadata.items() if key not in ("format", "members", "member_seeds")},
    )
    out = tmp_path / "ddqn.zip"
    result = CliRunner().invoke(app, ["export", str(member), "--sb3", str(out)])
    assert result.exit_code == 0, result.output
    sb3 = DQN.load(out, device="cpu")
    agent = load_agent(member)
    assert agent.metadata.kind == "lane-mlp"
    observations = np.random.default_rng(0).uniform(0, 1, (64, agent.observation_size)).astype(np.float32)
    np.testing.assert_array_equal(
        sb3.predict(observations, deterministic=True)[0], agent.q_values(observations).argmax(axis=1)
    )
    assert ("mobil_prior" in result.output) == bool(agent.metadata.mobil_prior)
    again = CliRunner().invoke(app, ["export", str(member), "--sb3", str(out)])
    assert again.exit_code == 2 and "exists" in again.output
    missing = CliRunner().invoke(
        app, ["export", str(tmp_path / "none.npz"), "--sb3", str(tmp_path / "x.zip")]
    )
    assert missing.exit_code == 2 and "no such model file" in missing.output


def test_the_ddqn_ships_one_small_data_only_model_for_every_road(tmp_path):
    """No model is picked by scenario: the one shipped file (within the issue's 1 MB) sees the road
    ego-relative with a lane code that does not depend on the lane count; --model wins."""
    shipped = SHIPPED_MODELS["ddqn"]
    assert shipped.stat().st_size <= 1_000_000
    assert sorted(path.name for path in shipped.parent.glob("ddqn*.npz")) == ["ddqn.npz"]
    agent = make_agent("ddqn", 4, GRID)
    assert agent.source == str(shipped)
    assert (agent.grid_config.lanes, agent.grid_config.lane_code) == ("ego", "sides")
    other = tmp_path / "other.npz"
    other.write_bytes(shipped.read_bytes())
    assert make_agent("ddqn", 4, GRID, model=other).source == str(other)


@pytest.mark.parametrize(
    "path", sorted(Path(SHIPPED_MODELS["ddqn"]).parent.glob("*.npz")), ids=lambda p: p.name
)
def test_every_shipped_model_s_metadata_reads_as_model_metadata_and_writes_its_keys_back(path):
    _, stored = load_model(path, arrays=False)
    metadata = ModelMetadata.from_json(stored)
    assert metadata.kind in ("mlp", "lane-mlp", "qtable") and metadata.grid == GridConfig(**stored["grid"])
    assert metadata.trained_steps is not None
    if metadata.members == 1:
        assert metadata.validation is not None and metadata.validation.step == metadata.trained_steps
    else:
        assert metadata.validation is None, "an ensemble's members were each kept by their own"
    written = metadata.to_json()
    assert list(written) == [key for key in stored if key != "format"], "the keys, in their order"
    validation = {"validation": stored["validation"]} if "validation" in stored else {}
    assert {**written, **validation} == {k: v for k, v in stored.items() if k != "format"}
    assert ModelMetadata.from_json(written) == metadata
