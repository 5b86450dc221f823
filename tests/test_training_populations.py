"""The shipped training config meets the drivers it is trained over in every world it learns from
(the mix, the demonstrations, the validation), never the held-out populations, and sees its sensor
worlds through the tracker."""

from pathlib import Path

import pytest

from stack.batch.closed_loop_batch import ClosedLoopBatch
from stack.settings.run import demonstration_worlds, drivers_of, episode_sensor, load_config, training_worlds
from stack.worlds.drivers import population_shares

SHIPPED = Path(__file__).resolve().parents[1] / "stack" / "configs" / "train" / "ddqn.yaml"
HELD_OUT = {"distracted", "blind"}


@pytest.fixture(scope="module")
def shipped():
    return load_config(SHIPPED)


def test_the_checkout_config_is_the_packaged_one():
    assert (SHIPPED.parents[3] / "configs" / "train" / "ddqn.yaml").read_text() == SHIPPED.read_text()


def test_every_world_learnt_from_draws_the_trained_populations(shipped):
    trained = drivers_of(shipped.highway)
    assert not HELD_OUT & set(population_shares(trained))
    learnt_from = {**training_worlds(shipped), **training_worlds(demonstration_worlds(shipped))}
    assert {name: drivers_of(world.highway) for name, world in learnt_from.items()} == dict.fromkeys(
        learnt_from, trained
    )


def test_the_sensor_worlds_are_tracked_and_the_others_not(shipped):
    worlds = training_worlds(shipped)
    seeds = range(20)
    tracked = {
        name: [world.perception.tracker.tracks(episode_sensor(world, seed)) for seed in seeds]
        for name, world in worlds.items()
    }
    assert all(tracked["noisy"]) and all(tracked["random"])
    assert not any(any(flags) for name, flags in tracked.items() if name not in ("noisy", "random"))


def test_the_training_batch_runs_the_tracker(shipped):
    loop = ClosedLoopBatch(shipped, 2)
    assert loop.tracker is not None
    loop.close()
