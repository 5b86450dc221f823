"""A driver who turned back in the middle of a lane change is kept a time gap to, not closed up on
beside (`controllers.weaving`)."""

import dataclasses
import math

import numpy as np
import pytest

from common.neighbours import WANDERING_M, between_lanes
from controllers.emergency import EmergencyBraking
from controllers.leaders import leaders
from controllers.weaving import WARY_S, WEAVE_MPS, WeaveMemory, turned_back
from records import Actuation, Neighbour, WorldState
from stack.batch.closed_loop_batch import ClosedLoopBatch
from stack.batch.loop_copies import copy_loop
from stack.loop.closed_loop import ClosedLoop
from stack.settings.run import build_config
from stack.sim.highway import HighwayAdapter
from stack.sim.safety_scenarios import LENGTH, Point, build, lane_centre

DT = 1 / 15
MOVER = 1


def test_a_vehicle_turned_back_only_when_it_reverses_between_lanes() -> None:
    offsets = np.array([0.0, 4.0, 8.0])
    assert between_lanes(4.0 + WANDERING_M + 0.5, offsets)
    assert not between_lanes(4.0 - WANDERING_M / 2, offsets)
    slow = WEAVE_MPS / 2
    assert turned_back(True, 1.0, 0.0) == (1.0, False)
    assert turned_back(True, 1.0, 1.0) == (1.0, False)
    assert turned_back(True, slow, 1.0) == (1.0, False)
    assert turned_back(True, -1.0, 1.0) == (-1.0, True)
    assert turned_back(False, -1.0, 1.0) == (0.0, False)
    assert turned_back(True, -1.0, 0.0) == (-1.0, False)


def placed(
    world: WorldState, ahead_m: float, d: float, heading: float, speed: float, time: float
) -> WorldState:
    """`world` at `time` [s] with the mover `ahead_m` [m] ahead of the ego (centres) at lateral
    position `d` [m], `heading` [rad] to the lane and `speed` [m/s]; the ego at 20 m/s in lane 1."""
    s, ds, headings, speeds = world.s.copy(), world.d.copy(), world.heading.copy(), world.speed.copy()
    s[MOVER], ds[MOVER], headings[MOVER], speeds[MOVER] = s[0] + ahead_m, d, heading, speed
    speeds[0] = 20.0
    return dataclasses.replace(world, s=s, d=ds, heading=headings, speed=speeds, time=time)


def weave(world: WorldState, memory: WeaveMemory, ahead_m: float, speed: float) -> WorldState:
    """The mover, in lane 2 next to the ego's lane 1, starts into the ego's lane and turns back to
    its lane's centre, seen by `memory` a tick at a time; returns the world once it is back."""
    centre, towards_ego = lane_centre(2), -0.1
    frames = [(centre - 0.6, towards_ego), (centre - 1.2, towards_ego), (centre - 1.0, -towards_ego)]
    frames.append((centre, 0.0))
    for tick, (d, heading) in enumerate(frames):
        world = placed(world, ahead_m, d, heading, speed, tick * DT)
        leaders(world, (1,), 1.0, weaves=memory)
    return world


def held_of(world: WorldState, memory: WeaveMemory, mover: int) -> list[Neighbour]:
    """The leaders of the ego's lane 1 that are the vehicle of id `mover`."""
    found = leaders(world, (1,), 1.0, weaves=memory, weaver_wary_s=WARY_S)
    return [leader for leader in found if leader.vehicle == mover]


@pytest.mark.parametrize(("ahead_m", "speed", "held"), [(15.0, 17.0, True), (5.5, 5.0, False)])
def test_a_driver_who_turned_back_is_kept_a_gap_to_unless_the_ego_is_past_sooner(
    ahead_m: float, speed: float, held: bool
) -> None:
    """A car in the next lane `ahead_m` ahead at `speed` (the ego at 20 m/s) that turned back from
    the ego's lane: the cruise keeps its gap to it for `WARY_S` (emergency braking waits), unless the
    ego, much faster and all but past, is by sooner than it could fall back."""
    road = build(Point("cut-out", (20.0, 60.0, 2.0)), 4, "kinematic", DT)
    world = road.reset()
    memory = WeaveMemory()
    back = weave(world, memory, ahead_m, speed)
    mover = int(world.ids[MOVER])
    found = held_of(back, memory, mover)
    assert not held_of(back, WeaveMemory(), mover)
    if not held:
        assert not found
        return
    (leader,) = found
    assert leader.may_turn_back and leader.gap == pytest.approx(ahead_m - LENGTH)
    assert EmergencyBraking(5.0, 3.0, 1.0).apply(Actuation(0.0, 0.0), 20.0, (leader,), DT).acceleration == 0.0
    later = dataclasses.replace(back, time=back.time + WARY_S + DT)
    assert not held_of(later, memory, mover)


def test_a_lane_change_carried_through_is_no_weave() -> None:
    road = build(Point("cut-out", (20.0, 60.0, 2.0)), 4, "kinematic", DT)
    world = road.reset()
    memory = WeaveMemory()
    for tick, d in enumerate(
        (lane_centre(2) - 0.6, lane_centre(2) - 2.0, lane_centre(1) + 0.6, lane_centre(1))
    ):
        world = placed(world, 15.0, d, -0.1 if tick < 3 else 0.0, 17.0, tick * DT)
        leaders(world, (0,), 1.0, weaves=memory)
    column = memory.column(int(world.ids[MOVER]))
    assert column is not None and math.isinf(memory.weaved_at[column])


def test_a_loop_copied_into_a_batch_keeps_what_it_remembers_of_weavers() -> None:
    """The oracle's batched search starts from a copy of the loop (`copy_loop`): each vehicle's weave
    memory is the batch's memory in that vehicle's slot."""
    config = build_config({"episodes": 1, "seed": 3, "highway": {"duration": 4}}, scenario="overtaking")
    with HighwayAdapter(config.highway, config.sim.backend) as adapter:
        loop = ClosedLoop(config, adapter)
        loop.reset(3)
        for _ in range(3):
            loop.tick()
        weaves, ids = loop.maneuver.weaves, loop.world.ids.tolist()
        column = weaves.column(ids[2])
        assert column is not None
        weaves.moving[column], weaves.weaved_at[column] = -1.0, 0.1
        batch = ClosedLoopBatch(config, 2)
        copy_loop(batch, [1], loop)
        assert batch.moving[1, 2] == -1.0 and batch.weaved_at[1, 2] == 0.1
        others = [row for row in range(1, len(ids)) if row != 2]
        assert not batch.moving[1, others].any() and np.isneginf(batch.weaved_at[1, others]).all()
        batch.close()


def test_a_config_written_before_the_weave_memory_existed_reads_it_off() -> None:
    """A folder's resolved config.yaml without `controller.weaver_wary_s` ran without the rule: it
    reads the key as 0 (with 0 the runs are those of the code before the rule); new configs hold
    `WARY_S`."""
    written = build_config({}).model_dump(mode="json")
    written["controller"].pop("weaver_wary_s")
    assert build_config(written).controller.weaver_wary_s == 0.0
    assert build_config({}).controller.weaver_wary_s == WARY_S


def test_a_tracked_world_s_memory_stays_with_its_tracks_when_another_world_grows_the_room() -> None:
    """A tracked world keeps each track's memory past the truth's columns (`vehicle_room` + 1 + the
    track's slot): when a world that resets with more vehicles grows the room, the columns move
    with it, so the track keeps what it had, as one world keeps it by the track's id."""
    config = build_config({"episodes": 1, "seed": 3, "highway": {"duration": 4}}, scenario="noisy")
    batch = ClosedLoopBatch(config, 1)
    batch.reset([3])
    assert batch.tracker is not None and bool(batch.tracker.tracked[0])
    room = batch.vehicle_room
    assert (batch.slots[0, 1:] > room).all()
    batch.moving[0, room + 1 + 3], batch.weaved_at[0, room + 1 + 3] = -1.0, 0.5
    batch._memory(room + 4)
    assert batch.moving[0, batch.vehicle_room + 1 + 3] == -1.0
    assert batch.weaved_at[0, batch.vehicle_room + 1 + 3] == 0.5
    batch.close()
