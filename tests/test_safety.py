import math
from dataclasses import replace

import numpy as np

from common.neighbours import lateral_drift, lateral_extent, neighbours, vehicle_rows
from controllers.maneuver import Maneuver
from planner.follower_forecast import follower_keeps_clear
from planner.safety import SafetyConfig, SafetyLayer, lane_is_safe
from records import Command, WorldState
from tests.helpers import cutting_in, scene


def with_speeds(world: WorldState, *speeds: float) -> WorldState:
    """`world` with its vehicles' speeds [m/s], row by row, heading along the road."""
    speed = np.array(speeds, dtype=float)
    return replace(world, speed=speed, velocity=np.stack([speed, np.zeros_like(speed)], axis=1))


def layer(**overrides) -> SafetyLayer:
    return SafetyLayer(SafetyConfig(**overrides))


def test_lane_change_off_the_road_is_masked():
    safety = layer()
    world = scene(3, (0.0, 0))
    assert safety.filter(Command.LEFT, world, lane=0) is Command.STAY
    assert safety.filter(Command.RIGHT, world, lane=0) is Command.RIGHT
    assert safety.masked == 1


def test_a_car_alongside_in_the_target_lane_masks_the_change():
    world = scene(3, (0.0, 1), [(2.0, 0.0)], speed=25.0, other_speed=25.0)
    safety = layer()
    assert safety.filter(Command.LEFT, world, lane=1) is Command.STAY
    assert safety.filter(Command.RIGHT, world, lane=1) is Command.RIGHT


def test_no_change_starts_while_a_car_is_alongside_in_the_lane_beyond_the_target():
    """Seed 634449 of `jam` (MOBIL): a change from lane 2 to 1 started beside a car in lane 0, which
    swerved into lane 1 at 0.6 rad; the abort could not turn the ego back in time at 4 m/s."""
    beside = scene(4, (0.0, 2), [(-1.0, 0.0)], speed=4.0, other_speed=5.0)
    safety = layer()
    assert safety.filter(Command.LEFT, beside, lane=2) is Command.STAY and safety.reacted_to == (1,)
    assert safety.filter(Command.RIGHT, beside, lane=2) is Command.RIGHT, "no lane beyond lane 3"
    assert layer(far_lane_gap_m=None).filter(Command.LEFT, beside, lane=2) is Command.LEFT
    # 10 m centre to centre, 5 m bumper to bumper: past the 2 m the default asks alongside (but
    # short of the 6 m a car ahead must leave, which the far lane's leader check asks)
    ahead = scene(4, (0.0, 2), [(10.0, 0.0)], 4.0, 5.0)
    assert layer(far_lane_leader=False).filter(Command.LEFT, ahead, lane=2) is Command.LEFT
    assert layer(far_lane_gap_m=6.0).filter(Command.LEFT, scene(4, (0.0, 2), [(10.0, 0.0)], 4.0, 5.0), 2) is (
        Command.STAY
    )


def test_no_change_starts_while_the_leader_of_the_lane_beyond_may_take_the_same_gap():
    """Seed 980153 of `lanes-5` (the lookahead): a change from lane 4 to 3 started 18 m behind a
    slower car in lane 2, which moved into lane 3 too; the ego braked at emergency strength."""
    world = with_speeds(scene(5, (0.0, 4), [(18.2, 8.0)]), 25.1, 22.0)
    safety = layer()
    assert safety.filter(Command.LEFT, world, lane=4) is Command.STAY and safety.reacted_to == (1,)
    assert layer(far_lane_leader=False).filter(Command.LEFT, world, lane=4) is Command.LEFT
    far_ahead = with_speeds(scene(5, (0.0, 4), [(60.0, 8.0)]), 25.1, 22.0)
    assert safety.filter(Command.LEFT, far_ahead, lane=4) is Command.LEFT


def test_no_change_that_forces_the_follower_to_brake_hard_while_the_ego_brakes_for_its_leader():
    """Seed 996541 of `incident` (MOBIL, aggressive drivers): braking for the stopped car ahead at
    13.8 m/s, the ego changed left in front of a car coming at 21.5 m/s, slowed to a crawl between the
    lanes and was hit. The follower, braking at 3 m/s^2 after 0.4 s, would not have stayed clear."""
    world = with_speeds(scene(2, (0.0, 1), [(47.4, 4.0), (-46.1, 0.0)]), 13.8, 0.0, 21.5)
    safety = layer()
    assert safety.filter(Command.LEFT, world, lane=1) is Command.STAY and safety.reacted_to == (2,)
    assert layer(follower_braking_mps2=None).filter(Command.LEFT, world, lane=1) is Command.LEFT
    no_stopped_car = with_speeds(scene(2, (0.0, 1), [(-46.1, 0.0)]), 13.8, 21.5)
    assert safety.filter(Command.LEFT, no_stopped_car, lane=1) is Command.LEFT


def test_the_follower_forecast_meets_the_stopping_distance():
    """A stopped ego and a follower at 20 m/s that reacts after 0.4 s and brakes at 3 m/s^2: it
    covers 8 + 400 / 6 = 74.7 m, so with 6 m to keep it needs 80.7 m."""
    kept = [follower_keeps_clear(gap, 20.0, 0.0, 0.0, 0.0, 3.0, 0.4, 6.0) for gap in (80.0, 82.0)]
    assert kept == [False, True]
    assert follower_keeps_clear(1.0, 20.0, 25.0, 0.0, 25.0, 3.0, 0.4, 0.5), "a slower follower"


def test_time_gap_and_ttc_to_the_vehicles_ahead_and_behind():
    # ahead in the target lane 15 m (gap 10 m) at 25 m/s: time gap 0.8 s x 25 = 20 m > 10 m -> unsafe
    assert layer().filter(Command.LEFT, scene(2, (0.0, 1), [(15.0, 0.0)], 25.0, 25.0), 1) is Command.STAY
    # far ahead but much slower: gap 55 m closing at 20 m/s, TTC 2.75 s < 4 s -> unsafe
    assert layer().filter(Command.LEFT, scene(2, (0.0, 1), [(60.0, 0.0)], 30.0, 10.0), 1) is Command.STAY
    # the same but slower ego: closing 5 m/s, TTC 11 s, gap 55 m > 12 m -> safe
    assert layer().filter(Command.LEFT, scene(2, (0.0, 1), [(60.0, 0.0)], 15.0, 10.0), 1) is Command.LEFT
    # a fast car coming from behind: gap 35 m closing at 10 m/s (3.5 s) -> unsafe
    assert layer().filter(Command.LEFT, scene(2, (0.0, 1), [(-40.0, 0.0)], 20.0, 30.0), 1) is Command.STAY
    # the same car slower than the ego -> safe
    assert layer().filter(Command.LEFT, scene(2, (0.0, 1), [(-40.0, 0.0)], 25.0, 20.0), 1) is Command.LEFT


def test_abort_when_the_gap_closes_and_switch_off_for_ablation():
    closing = scene(2, (0.0, 1), [(-8.0, 0.0)], speed=20.0, other_speed=30.0)
    safety = layer()
    assert safety.should_abort(closing, lane=1, target=0)
    assert safety.aborted == 1
    off = layer(enabled=False)
    assert not off.should_abort(closing, lane=1, target=0)
    assert off.filter(Command.LEFT, closing, 1) is Command.LEFT
    assert off.masked == 0


def test_at_crawl_speed_a_gap_is_judged_in_metres():
    # 2 m/s: 0.8 s x 2 m/s = 1.6 m, but the gap must still be 6 m: 4 m (9 m centre to centre) is refused
    crawl = scene(2, (0.0, 1), [(9.0, 0.0)], speed=2.0, other_speed=2.0)
    assert layer().filter(Command.LEFT, crawl, 1) is Command.STAY
    assert layer().filter(Command.LEFT, scene(2, (0.0, 1), [(12.0, 0.0)], 2.0, 2.0), 1) is Command.LEFT


def test_a_car_nosing_into_the_lane_is_seen_there_by_its_turned_footprint():
    world = scene(3, (0.0, 2), [(8.0, 4.9)], speed=12.0, other_speed=0.0)
    assert neighbours(world, 2)[0] is None
    heading = world.heading.copy()
    heading[1] = math.radians(33.0)
    nosing = type(world)(**{**world.__dict__, "heading": heading})
    leader = neighbours(nosing, 2)[0]
    assert leader is not None and leader.gap == 3.0
    assert np.isclose(lateral_extent(nosing)[0], 5 * math.sin(heading[1]) + 2 * math.cos(heading[1]))


def test_an_abort_sees_a_car_cutting_into_the_target_lane_before_it_arrives():
    cut_in = cutting_in(-0.3)
    assert neighbours(cut_in, 1)[0] is None
    assert layer().should_abort(cut_in, lane=0, target=1)
    assert not layer(abort_lookahead_s=0.0).should_abort(cut_in, lane=0, target=1)
    assert not layer().should_abort(cutting_in(0.3), lane=0, target=1), "a car turning away is no threat"
    assert not layer(abort_lookahead_s=0.2).should_abort(cut_in, lane=0, target=1), "0.9 m/s x 0.2 s: not yet"


def test_a_change_goes_on_when_the_car_closing_its_gap_crosses_the_origin_lane_on_its_way():
    """The ego, 18 m/s, half way from lane 1 towards lane 0 (centre at 2.5 m); a car 1.3 m ahead
    (centres) at 20.7 m/s, cutting across from lane 2, is in lane 1 at 5.7 m turned 0.19 rad towards
    lane 0 (3.9 m/s sideways, a blind driver): within the abort's 1-s lookahead it reaches lane 0,
    which is then unsafe, but it is in lane 1 now, so turning back is no safer, and the change goes
    on (a development episode: the ego turned back into the car's side). With the origin lane free
    the change is given up (`test_an_abort_sees_a_car_cutting_into_the_target_lane_before_it_arrives`)."""
    world = scene(3, (0.0, 1), [(1.3, 5.7)], speed=18.0, other_speed=20.7)
    world = type(world)(**{**world.__dict__, "heading": np.array([0.0, -0.19]), "d": np.array([2.5, 5.7])})
    rows = vehicle_rows(world)._replace(drift=np.concatenate(([0.0], lateral_drift(world, 1.0))))
    assert not lane_is_safe(rows, 0.0, 2.0, 1.5, 0.0, 0.0) and not lane_is_safe(rows, 4.0, 2.0, 1.5, 0.0, 0.0)
    assert not layer().should_abort(world, lane=1, target=0)


def test_a_change_is_given_up_though_the_origin_lane_s_leader_is_closing():
    """Around a stopped car 11 m ahead (gap 6 m) at 5 m/s (TTC 1.2 s, under the abort's 1.5 s),
    half way to lane 0, where a car 8 m behind closes at 10 m/s: the ego turns back and brakes for
    the stopped car, as it would have had it never left; only a car within the abort gap there, or
    closing from behind, holds it in the target lane."""
    world = scene(2, (0.0, 1), [(11.0, 4.0), (-8.0, 0.0)], speed=5.0, other_speed=0.0)
    speed = np.array([5.0, 0.0, 15.0])
    world = type(world)(**{**world.__dict__, "speed": speed, "d": np.array([2.5, 4.0, 0.0])})
    assert layer().should_abort(world, lane=1, target=0)


def test_after_an_abort_the_cruise_follows_the_abandoned_lane_until_the_ego_is_out_of_it():
    world = scene(2, (0.0, 1), [(-8.0, 0.0), (12.0, 0.0)], speed=20.0, other_speed=30.0)
    maneuver = Maneuver(world, 4.0, 30.0, should_abort=layer().should_abort)
    assert maneuver.command(Command.LEFT, world)
    straddling = type(world)(**{**world.__dict__, "d": np.array([2.5, 0.0, 0.0]), "time": 1.0})
    reference = maneuver.reference(straddling)
    assert not maneuver.changing_lane, "the car closing from behind aborts the change"
    assert [leader.gap for leader in reference.leaders] == [7.0], "the abandoned lane's leader, 7 m ahead"
    home = type(world)(**{**world.__dict__, "time": 2.0})
    assert maneuver.reference(home).leaders == ()


def test_no_new_change_starts_until_an_aborted_one_has_returned_to_the_lane_centre():
    """Seed 1063029 of `incident` (MOBIL): a change given up half way was followed a tick later by
    one to the other side, across the origin lane, from between lanes with the car still pointing
    at the lane it gave up; braking for a stopped car there, it stood across the lane line and was
    hit from behind. A new change starts only once the reference is back at the lane centre."""
    world = scene(2, (0.0, 1), [(-8.0, 0.0), (12.0, 0.0)], speed=20.0, other_speed=30.0)
    maneuver = Maneuver(world, 4.0, 30.0, should_abort=layer().should_abort)
    assert maneuver.command(Command.LEFT, world)
    at = lambda t: type(world)(**{**world.__dict__, "d": np.array([2.5, 0.0, 0.0]), "time": t})  # noqa: E731
    maneuver.reference(at(1.0))
    assert not maneuver.changing_lane
    maneuver.reference(at(1.5))
    assert not maneuver.command(Command.LEFT, at(1.5)), "still returning: refused"
    maneuver.reference(at(3.1))
    assert maneuver.command(Command.LEFT, at(3.1)), "back at the centre 2 s after the abort"
    assert maneuver.lane_changes == 2


def test_a_change_whose_footprint_has_left_the_origin_lane_no_longer_follows_that_lane():
    """A car stopped 15 m ahead in the origin lane holds the cruise while the ego still reaches
    into that lane, and no longer once its footprint has left it (else the braking slows the
    change, which keeps the lane listed, down to a stop across the target lane)."""
    world = scene(2, (0.0, 1), [(15.0, 4.0)], speed=10.0, other_speed=0.0)
    maneuver = Maneuver(world, 4.0, 30.0)
    assert maneuver.command(Command.LEFT, world)
    at = lambda d, t: type(world)(**{**world.__dict__, "d": np.array([d, 4.0]), "time": t})  # noqa: E731
    assert [leader.gap for leader in maneuver.reference(at(3.0, 1.0)).leaders] == [10.0]
    assert maneuver.changing_lane and maneuver.reference(at(0.5, 2.0)).leaders == ()
