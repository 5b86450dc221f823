"""The lane network (`train.network: lanes`): every grid row through one encoder shared by all
lanes, then a head; trained through SB3's features extractor, saved as a `lane-mlp` file that
loads to the same Q-values, refused in one line when its arrays or its grid do not fit."""

import csv

import gymnasium as gym
import numpy as np
import pytest
import torch as th
import yaml
from typer.testing import CliRunner

from perception.grid import OccupancyGridBuilder
from planner.ddqn import DoubleDQN
from planner.lane_network import LaneFeatures
from planner.learned import export_q_network, load_agent
from planner.model_file import ModelFileError, load_model, save_model
from planner.model_metadata import ModelMetadata
from planner.networks import LANE_ENCODER, NET_ARCHS, lane_columns
from records import N_ACTIONS, GridConfig
from stack.apps.cli import app
from stack.training.model import warm_start
from tests.helpers import scene
from tests.test_train import TINY, trained

GRID = GridConfig(
    lanes="ego", lateral_reach=2, lane_code="sides", cells_ahead=8, cells_behind=2,
    features=("relative_speed", "ttc", "ego_speed"),
)  # fmt: skip
SIZE = 5 * 10 * 2 + 5 + 1 + 2 + N_ACTIONS
"""Presence and relative speed of 5 rows x 10 cells, a TTC a row, the ego speed, the lane part and
the permitted commands."""
METADATA = ModelMetadata(
    kind="mlp", algorithm="ddqn", encoding="observation", observation_size=SIZE,
    hidden=tuple(NET_ARCHS["lanes"]), grid=GRID, action_mask=True,
)  # fmt: skip
"""What a lane network of GRID's observations is saved with (`export_q_network` sets the kind)."""
LANES = {
    **TINY,
    "perception": {**TINY["perception"], "lane_code": "sides"},
    "train": {**TINY["train"], "network": "lanes", "action_mask": True},
}


def observation() -> np.ndarray:
    world = scene(4, (0.0, 1), [(12.0, 4.0), (30.0, 0.0), (-6.0, 8.0), (40.0, 12.0)], other_speed=18.0)
    encoded = OccupancyGridBuilder(GRID).build(world).to_observation()
    return np.concatenate([encoded, [1.0, 1.0, 0.0]]).astype(np.float32)


def test_each_row_of_the_lane_network_reads_its_lane_s_values():
    values = observation()
    rows, rest = lane_columns(GRID, SIZE)
    parts = GRID.observation_parts(4)
    presence = values[parts["presence"]].reshape(5, 10)
    speeds = values[parts["relative_speed"]].reshape(5, 10)
    ttc = values[parts["ttc"]]
    for row in range(5):
        expected = np.concatenate([presence[row], speeds[row], [ttc[row]]])
        np.testing.assert_array_equal(values[rows[row]], expected)
    assert presence[1:4].any(axis=1).all(), "the scene puts a vehicle in the ego's lane and beside it"
    np.testing.assert_array_equal(rest, np.arange(parts["ego_speed"].start, SIZE))


def test_one_encoder_serves_every_lane():
    features = LaneFeatures(gym.spaces.Box(-1.0, 1.0, (SIZE,)), GRID)
    rows, rest = lane_columns(GRID, SIZE)
    values = observation()
    swapped = values.copy()
    swapped[rows[1]], swapped[rows[3]] = values[rows[3]], values[rows[1]]
    with th.no_grad():
        codes = features(th.as_tensor(np.stack([values, swapped]))).numpy()
    width = LANE_ENCODER[-1]
    lane = [slice(row * width, (row + 1) * width) for row in range(5)]
    np.testing.assert_array_equal(codes[0, lane[1]], codes[1, lane[3]])
    np.testing.assert_array_equal(codes[0, lane[3]], codes[1, lane[1]])
    np.testing.assert_array_equal(codes[0, lane[0]], codes[1, lane[0]])
    np.testing.assert_array_equal(codes[0, 5 * width :], values[rest])
    assert not np.array_equal(codes[0, lane[1]], codes[0, lane[3]]), "different lanes, different codes"


def lane_dqn(steps: int = 64) -> DoubleDQN:
    space = gym.spaces.Box(-1.0, 1.0, (SIZE,), np.float32)
    start = observation()

    class OneScene(gym.Env):
        observation_space, action_space = space, gym.spaces.Discrete(3)

        def reset(self, *, seed=None, options=None):
            return start, {}

        def step(self, action):
            return start, float(action), True, False, {}

    options = {"features_extractor_class": LaneFeatures, "features_extractor_kwargs": {"grid": GRID}}
    model = DoubleDQN(
        "MlpPolicy", OneScene(), learning_starts=0, batch_size=8, seed=0,
        policy_kwargs={"net_arch": NET_ARCHS["lanes"], **options},
    )  # fmt: skip
    model.learn(steps)
    return model


def test_a_trained_lane_network_saves_and_loads_to_the_same_q_values(tmp_path):
    model = lane_dqn()
    path = export_q_network(model, tmp_path / "lanes.npz", METADATA)
    assert load_model(path)[1]["kind"] == "lane-mlp"
    agent = load_agent(path)
    batch = np.random.default_rng(3).uniform(-1, 1, (16, SIZE)).astype(np.float32)
    with th.no_grad():
        expected = model.policy.q_net(th.as_tensor(batch)).numpy()
    np.testing.assert_array_equal(agent.q_values(batch), expected)


def test_a_lane_network_file_starts_a_run_as_the_network_it_saved(tmp_path):
    trained_model = lane_dqn()
    start = load_agent(export_q_network(trained_model, tmp_path / "lanes.npz", METADATA))
    fresh = lane_dqn(steps=0)
    warm_start(fresh, start)
    batch = th.as_tensor(np.random.default_rng(4).uniform(-1, 1, (16, SIZE)).astype(np.float32))
    with th.no_grad():
        expected = trained_model.policy.q_net(batch).numpy()
        np.testing.assert_array_equal(fresh.policy.q_net(batch).numpy(), expected)
        np.testing.assert_array_equal(fresh.policy.q_net_target(batch).numpy(), expected)


def test_a_lane_network_file_that_does_not_fit_is_refused_in_one_line(tmp_path):
    path = export_q_network(
        lane_dqn(),
        tmp_path / "lanes.npz",
        ModelMetadata(kind="mlp", encoding="observation", observation_size=SIZE, hidden=(128, 64), grid=GRID),
    )
    arrays, metadata = load_model(path)
    cut = {**arrays, "head.0.weight": arrays["head.0.weight"][:, :-1]}
    save_model(tmp_path / "cut.npz", cut, metadata)
    with pytest.raises(ModelFileError, match="model arrays do not match its metadata"):
        load_agent(tmp_path / "cut.npz")
    binary = {**metadata, "grid": {**metadata["grid"], "lane_code": "binary"}}
    save_model(tmp_path / "binary.npz", arrays, binary)
    with pytest.raises(ModelFileError, match="grid: the lanes network reads the observation encoding"):
        load_agent(tmp_path / "binary.npz")


def test_train_with_the_lane_network_and_drive_with_its_model(tmp_path):
    config, out = trained(tmp_path, LANES)
    _, metadata = load_model(out / "best.npz")
    assert metadata["kind"] == "lane-mlp" and metadata["hidden"] == NET_ARCHS["lanes"]
    drive = tmp_path / "drive"
    options = ["--agent", "ddqn", "--model", str(out / "best.npz"), "--episodes", "2", "--no-progress"]
    run = CliRunner().invoke(app, ["run", "-c", str(config), *options, "--out", str(drive)])
    assert run.exit_code == 0, run.output
    with open(drive / "episodes.csv") as episodes:
        assert [row["masked_commands"] for row in csv.DictReader(episodes)] == ["0", "0"]


def test_the_lane_network_needs_rows_around_the_ego_and_their_side_lanes(tmp_path):
    config = tmp_path / "absolute.yaml"
    config.write_text(yaml.safe_dump({**LANES, "perception": {**LANES["perception"], "lane_code": "binary"}}))
    result = CliRunner().invoke(app, ["train", "-c", str(config), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "train.network: the lanes network reads" in result.output
    assert not (tmp_path / "o").exists()
