"""The fast backend must reproduce stock highway-env exactly: every vehicle, every frame."""

import gymnasium as gym
import numpy as np
import pytest

from stack.core.config import ConfigError, HighwayConfig, build_config
from stack.sim.envs import FAST_HIGHWAY
from stack.sim.highway import HighwayAdapter, env_config


def ramming(frame: int) -> np.ndarray:
    """An ego at full throttle with a slight weave: it rear-ends traffic; frames go on after the
    crash, so the crash physics (impact, braking to a stop) is compared too."""
    return np.array([1.0, 0.02 * np.sin(frame / 15.0)])


def trajectory(env_id: str, highway: HighwayConfig, seed: int, frames: int) -> list[np.ndarray]:
    env = gym.make(env_id, config=env_config(highway), disable_env_checker=True)
    env.reset(seed=seed)
    states = []
    for frame in range(frames):
        _, _, _, truncated, _ = env.step(ramming(frame))
        states.append(
            np.array(
                [
                    [*v.position, v.heading, v.speed, v.lane_index[2], v.crashed]
                    for v in env.unwrapped.road.vehicles
                ]
            )
        )
        if truncated:
            break
    env.close()
    return states


def assert_identical(highway: HighwayConfig, seed: int, frames: int) -> list[np.ndarray]:
    stock = trajectory("highway-v0", highway, seed, frames)
    fast = trajectory(FAST_HIGHWAY, highway, seed, frames)
    assert len(fast) == len(stock)
    for frame, (a, b) in enumerate(zip(stock, fast, strict=True)):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9, err_msg=f"frame {frame}")
    return stock


def traffic_lane_changes(states: list[np.ndarray]) -> int:
    lanes = np.array([s[1:, 4] for s in states])
    return int(np.count_nonzero(np.diff(lanes, axis=0)))


@pytest.mark.parametrize(
    ("seed", "density", "vehicles", "frames"),
    [(0, 1.0, 50, 200), (1, 1.0, 50, 200), (2, 2.0, 100, 120)],
)
def test_fast_backend_matches_stock(seed, density, vehicles, frames):
    highway = HighwayConfig(vehicles_count=vehicles, vehicles_density=density)
    assert_identical(highway, seed, frames)


def test_the_short_runs_cover_crashes_and_traffic_lane_changes():
    states = assert_identical(HighwayConfig(vehicles_count=50), seed=1, frames=200)
    assert states[-1][:, 5].sum() >= 2, "the ramming ego must crash into someone"
    assert traffic_lane_changes(states) > 0


@pytest.mark.parametrize("lanes", [2, 3, 5])
def test_fast_backend_matches_stock_on_other_lane_counts(lanes):
    assert_identical(HighwayConfig(lanes_count=lanes, vehicles_count=30), seed=lanes, frames=150)


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "density"), [(0, 1.0), (1, 1.5), (2, 2.0)])
def test_fast_backend_matches_stock_over_full_episodes(seed, density):
    states = assert_identical(HighwayConfig(vehicles_density=density), seed, frames=600)
    assert len(states) == 600, "every frame of the 40 s episode was compared"


def test_unknown_backend_is_refused_with_the_list():
    with pytest.raises(ConfigError, match="sim.backend: unknown backend 'turbo'; available: fast, stock"):
        build_config({"sim": {"backend": "turbo"}})
    with pytest.raises(ValueError, match="available: fast, stock"):
        HighwayAdapter(HighwayConfig(), backend="turbo")
