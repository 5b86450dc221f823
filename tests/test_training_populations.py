"""The training config over driver populations (`ddqn-populations.yaml`) meets the drivers it is
trained over in every world it learns from (the mix, the demonstrations, the validation), never the
held-out populations, and sees its sensor worlds through the tracker."""

from pathlib import Path

import pytest

from stack.batch.closed_loop_batch import ClosedLoopBatch
from stack.settings.run import demonstration_worlds, drivers_of, episode_sensor, load_config, training_worlds
from stack.worlds.drivers import population_shares

PACKAGED = Path(__file__).resolve().parents[1] / "stack" / "configs" / "train"
POPULATIONS = PACKAGED / "ddqn-populations.yaml"
HELD_OUT = {"distracted", "blind"}


@pytest.fixture(scope="module")
def populations():
    return load_config(POPULATIONS)


@pytest.mark.parametrize("name", ["ddqn.yaml", "ddqn-populations.yaml"])
def test_the_checkout_config_is_the_packaged_one(name):
    assert (PACKAGED.parents[2] / "configs" / "train" / name).read_text() == (PACKAGED / name).read_text()


def test_every_world_learnt_from_draws_the_trained_populations(populations):
    trained = drivers_of(populations.highway)
    assert not HELD_OUT & set(population_shares(trained))
    learnt_from = {**training_worlds(populations), **training_worlds(demonstration_worlds(populations))}
    assert {name: drivers_of(world.highway) for name, world in learnt_from.items()} == dict.fromkeys(
        learnt_from, trained
    )


def test_the_sensor_worlds_are_tracked_and_the_others_not(populations):
    worlds = training_worlds(populations)
    seeds = range(20)
    tracked = {
        name: [world.perception.tracker.tracks(episode_sensor(world, seed)) for seed in seeds]
        for name, world in worlds.items()
    }
    assert all(tracked["noisy"]) and all(tracked["random"])
    assert not any(any(flags) for name, flags in tracked.items() if name not in ("noisy", "random"))


def test_the_training_batch_runs_the_tracker(populations):
    loop = ClosedLoopBatch(populations, 2)
    assert loop.tracker is not None
    loop.close()
