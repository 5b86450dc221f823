"""`drivestack safety`: the reference driver against hand-computed stopping distances, each
scenario's geometry, an assessment that can fail (a stack that never brakes), the failures found
on the way kept as regression points, and a CLI smoke run on a tiny grid."""

import dataclasses
import json
import math

import pytest
from typer.testing import CliRunner

from controllers.emergency import EmergencyBraking
from controllers.leaders import leaders, passes_sooner_than_falls_back
from controllers.reference import QuinticProfile, road_to_reach
from records import Actuation, Neighbour
from stack.apps.cli import app
from stack.assessment.safety_assessment import assess, drive_reference
from stack.fault.reference_driver import CarefulDriver, stopping_distance
from stack.settings.run import build_config
from stack.sim import safety_scenarios
from stack.sim.safety_scenarios import LENGTH, Point, build, grid, parse_point
from stack.sim.scripted_road import EGO_START_S, Actor, ScriptedRoad

DT = 1 / 15


def test_stopping_distance_matches_the_hand_computation():
    # 20 m/s: 1.15 s of delay (23 m), a 0.6 s ramp to 5 m/s^2 (20 * 0.6 - 5 * 0.6^2 / 6 = 11.7 m,
    # leaving 20 - 1.5 = 18.5 m/s), then 18.5^2 / (2 * 5) = 34.225 m at full braking
    assert stopping_distance(20.0, 1.15, 0.6, 5.0) == pytest.approx(23.0 + 11.7 + 34.225)
    # 36.1 m/s: 41.515 + (21.66 - 0.3) + 34.6^2 / 10
    assert stopping_distance(36.1, 1.15, 0.6, 5.0) == pytest.approx(41.515 + 21.36 + 119.716)


class Stationary:
    """A script with nothing to start: one stationary vehicle far ahead."""

    def update(self, time, ego_s, actors):
        pass

    def settled(self, actors):
        return True


@pytest.mark.parametrize("plant", ["kinematic", "dynamic"])
@pytest.mark.parametrize("speed", [10.0, 20.0, 36.1])
def test_careful_driver_stops_in_the_hand_computed_distance(plant, speed):
    road = ScriptedRoad(4, 1, speed, [Actor(EGO_START_S + 900.0, 4.0, 0.0)], Stationary(), plant, DT, 60.0)
    world = road.reset()
    driver = CarefulDriver()
    driver.risk_at = 0.0
    while world.speed[0] > 0:
        world = road.step(driver.step(world, DT))
    travelled = road.ego_s - EGO_START_S
    # the control ticks sample the delay and the ramp (up to a tick late) and the plant integrates
    # position before speed (forward Euler, v dt / 2 farther): at most 1.5 v dt beyond
    expected = stopping_distance(speed, 1.15, 0.6, 5.0)
    assert expected <= travelled <= expected + 1.5 * speed * DT


def hold_speed(point: Point):
    """`point`'s plant with the ego holding its speed; returns the plant after the script played."""
    road = build(point, 4, "kinematic", DT)
    road.reset()
    while not road.script.settled(road.actors) and road.ticks < 600:
        road.step(Actuation(0.0, 0.0))
    return road


def test_lead_braking_leader_brakes_at_the_given_gap_and_deceleration():
    road = hold_speed(Point("lead-braking", (25.0, 1.2, 6.0)))
    assert road.script.started_at == pytest.approx(safety_scenarios.BRAKE_AT_S)
    assert road.script.gap_at_start == pytest.approx(1.2 * 25.0)
    assert road.actors[0].braking == 6.0 and road.actors[0].speed == 0.0


@pytest.mark.parametrize("relative_speed", [0.0, 4.0])
def test_cut_in_starts_at_the_given_gap_and_ends_in_the_ego_lane(relative_speed):
    road = build(Point("cut-in", (30.0, relative_speed, 12.0, 1.5)), 4, "kinematic", DT)
    road.reset()
    while road.script.started_at is None:
        road.step(Actuation(0.0, 0.0))
    assert road.script.gap_at_start == pytest.approx(12.0, abs=relative_speed * DT + 1e-9)
    cutter = road.actors[0]
    assert cutter.d == pytest.approx(8.0) and cutter.speed == 30.0 - relative_speed
    road.step(Actuation(0.0, 0.0))
    assert 8.0 - cutter.d == pytest.approx(1.5 * DT)
    while not road.script.settled(road.actors):
        road.step(Actuation(0.0, 0.0))
    assert cutter.d == 4.0


def test_cut_out_reveals_a_stationary_vehicle_at_the_given_distance():
    road = build(Point("cut-out", (30.0, 120.0, 2.0)), 4, "kinematic", DT)
    road.reset()
    while road.script.started_at is None:
        road.step(Actuation(0.0, 0.0))
    assert road.script.gap_at_start == pytest.approx(120.0, abs=30.0 * DT)
    leader, stationary = road.actors
    assert leader.s - road.ego_s - LENGTH == pytest.approx(1.5 * 30.0 + 8.0)
    assert (stationary.speed, stationary.d, leader.target_d) == (0.0, 4.0, 8.0)


def test_grids_hold_at_least_500_points_per_type_and_parse_back():
    for kind in safety_scenarios.SCENARIO_KINDS:
        points = grid(kind)
        assert len(points) >= 500
        assert parse_point(kind, points[7].text) == points[7]
    with pytest.raises(ValueError, match="missing gap"):
        parse_point("cut-in", "speed=20,relative_speed=2,lateral_speed=1")


def test_a_stack_that_never_brakes_fails_points_the_reference_driver_passes():
    config = build_config(
        {
            "planner": {"agent": "keep-lane"},
            "controller": {"comfort_decel_mps2": 0.01, "emergency_decel_mps2": 0.01, "emergency_ttc_s": 0.0},
        }
    )
    for point in (Point("lead-braking", (20.0, 2.0, 4.0)), Point("cut-out", (15.0, 60.0, 2.0))):
        assessed = assess((config, point))
        assert assessed.stack.collided and not assessed.reference.collided
        assert assessed.outcome == "failure"


REGRESSIONS = [
    "pid kinematic lead-braking speed=36.11,time_gap=2.5,deceleration=5",
    "pid kinematic cut-in speed=13.89,relative_speed=6,gap=10,lateral_speed=0.5",
    "pid kinematic cut-in speed=19.44,relative_speed=6,gap=10,lateral_speed=0.5",
    "pid kinematic cut-out speed=22.22,distance=100,lateral_speed=1",
    "pid kinematic cut-out speed=27.78,distance=200,lateral_speed=0.5",
    "pid kinematic cut-out speed=36.11,distance=200,lateral_speed=1.5",
    "mpc dynamic lead-braking speed=5.56,time_gap=1,deceleration=2",
    "mpc dynamic cut-out speed=8.33,distance=30,lateral_speed=1",
]
"""Failures of the default agent (ddqn) found by the full grids: a braking leader seen too late,
a slow car cutting in beside the ego braked for instead of passed, a stationary car hidden by a
leader that was leaving the lane (PID, kinematic plant); the MPC on its dynamic model creeping
into a stopped leader at crawl speed (dynamic plant)."""


@pytest.mark.parametrize("case", REGRESSIONS)
def test_failures_found_on_the_way_stay_avoided(case):
    controller, plant, kind, text = case.split()
    config = build_config(
        {"planner": {"agent": "ddqn"}, "controller": {"type": controller}, "sim": {"plant": plant}}
    )
    assessed = assess((config, parse_point(kind, text)))
    assert not assessed.reference.collided and not assessed.stack.collided


POOR_SENSOR = {"position_noise_m": 1.0, "miss_probability": 0.1, "false_positives": 0.5}
"""The sensor of the grids' poor-sensor runs (tracked)."""


@pytest.mark.parametrize(
    "text",
    [
        "speed=25,relative_speed=6,gap=10,lateral_speed=0.5",
        "speed=25,relative_speed=4,gap=3,lateral_speed=0.5",
    ],
)
def test_slow_cut_ins_seen_through_a_poor_sensor_stay_avoided(text):
    """Failures of the full cut-in grid through a poor sensor: a pass that 4 cm of tracked position
    turned into braking beside the car, and a slow cut-in 3 m ahead whose tracked direction
    flickered with the filtered velocity's noise."""
    config = build_config({"planner": {"agent": "ddqn"}, "perception": {"sensor": POOR_SENSOR}})
    assessed = assess((config, parse_point("cut-in", text)))
    assert not assessed.reference.collided and not assessed.stack.collided


def test_braking_leader_triggers_emergency_braking_before_the_constant_speed_prediction():
    brake = EmergencyBraking(5.0, 3.0, 1.0)
    cruise = Actuation(-3.0, 0.0)
    for tick in range(3):
        leader = Neighbour(gap=90.0, speed=36.0 - 5.0 * DT * tick, vehicle=7)
        acted = brake.apply(cruise, 36.0, (leader,), DT)
    assert acted.acceleration == -5.0 and brake.activations == 1
    assert not EmergencyBraking(5.0, 3.0, 1.0).needed(36.0, (leader,))


def test_leaving_leader_no_longer_hides_the_vehicle_beyond():
    road = build(Point("cut-out", (20.0, 60.0, 2.0)), 4, "kinematic", DT)
    world = road.reset()
    assert len(leaders(world, (1,))) == 1
    while road.actors[0].d < 5.5:
        world = road.step(Actuation(0.0, 0.0))
    assert [leader.speed for leader in leaders(world, (1,))] == [20.0, 0.0]


def test_a_car_cutting_in_is_a_leader_before_it_reaches_the_lane():
    """1.5 m/s sideways, 12 m ahead: once it moves, its footprint reaches the ego's lane within the
    cut-in lookahead (1 s) before it reaches it; with none the cruise waits until it is in."""
    road = build(Point("cut-in", (30.0, 4.0, 12.0, 1.5)), 4, "kinematic", DT)
    world = road.reset()
    while road.script.started_at is None or road.actors[0].d > 7.6:
        world = road.step(Actuation(0.0, 0.0))
        assert leaders(world, (1,)) == ()
    assert leaders(world, (1,), cut_in_lookahead_s=0.0) == ()
    (anticipated,) = leaders(world, (1,), cut_in_lookahead_s=1.0)
    assert anticipated.speed == road.actors[0].speed
    assert leaders(world, (2,), cut_in_lookahead_s=1.0)[0].vehicle == anticipated.vehicle


def test_the_road_a_lane_change_needs_is_the_course_s_geometry_at_a_crawl():
    """A 4 m change over 5 s reaches its middle after 2.5 s of its profile: 75 m at 30 m/s; at
    1 m/s its clock slows with the car, so the road is 2.5 s x peak lateral speed / tan(12 deg)."""
    profile = QuinticProfile(d0=0.0, d1=4.0, t0=0.0, duration=5.0)
    c = tuple(profile.coefficients.tolist())
    tan_course, step = math.tan(math.radians(12.0)), 5.0 / 64
    for speed, per_second in ((30.0, 30.0), (1.0, profile.peak_lateral_speed / tan_course)):
        road = road_to_reach(*c, 0.0, 5.0, 4.0, 0.0, 2.0, 1.0, speed, tan_course, profile.peak_lateral_speed)
        assert 2.5 * per_second <= road <= (2.5 + step) * per_second
    assert road_to_reach(*c, 0.0, 5.0, 4.0, 0.0, 5.0, 1.0, 30.0, tan_course, 1.0) == math.inf


@pytest.mark.parametrize(("road_to_leave", "followed"), [(10.0, False), (15.0, True)])
def test_a_stopped_car_in_the_lane_being_left_is_passed_when_the_change_leaves_it_first(
    road_to_leave, followed
):
    """20 m ahead in the lane a change is leaving: not followed while the change is out of that lane
    within 1.5 x its road (plus 1 m), else followed; in other lanes always."""
    stopped = Actor(EGO_START_S + LENGTH + 20.0, safety_scenarios.lane_centre(1), 0.0)
    world = ScriptedRoad(4, 1, 3.0, [stopped], Stationary(), "kinematic", DT, 5.0).reset()
    assert len(leaders(world, (1,), 0.0, 1, road_to_leave)) == followed
    assert len(leaders(world, (1,), 0.0, 2, road_to_leave)) == 1


@pytest.mark.parametrize(
    ("rel_s", "closing", "passes"),
    [(3.6, 6.0, True), (3.6, 0.5, False), (6.0, 6.0, True), (15.0, 6.0, False)],
)
def test_a_slower_car_alongside_is_passed_when_passing_is_sooner_than_falling_back(rel_s, closing, passes):
    """Two 5 m cars, the other's centre `rel_s` ahead: 1.4 m beside it at 6 m/s faster the ego is
    past it in 1.43 s, behind it braking at 5 m/s^2 only after 2.6 s; at 0.5 m/s faster it falls
    back in 0.85 s; 1 m behind it at 6 m/s faster it cannot stop short of it (3.6 m needed) and is
    past in 1.83 s, behind it again after 2.22 s; 10 m behind, braking keeps it behind."""
    assert passes_sooner_than_falls_back(rel_s, closing, 5.0) == passes


@pytest.mark.parametrize(
    ("d", "speed", "heading", "rel_s", "followed"),
    [
        (5.5, 0.0, 0.0, 65.0, True),
        (7.4, 15.0, -0.1, 13.0, True),
        (7.0, 3.5, -0.13, 31.0, True),
        (7.13, 19.0, -0.026, 5.06, False),
    ],
)
def test_a_car_the_ego_cannot_stop_short_of_is_passed_only_if_it_does_not_touch_it_first(
    d, speed, heading, rel_s, followed
):
    """The ego at 25 m/s in the lane centred at d = 4 m, a 5 m car `rel_s` ahead (centres) that
    braking at 5 m/s^2 cannot keep it behind: a stopped car reaching 0.5 m into the ego's path is
    followed; one drifting in at 1.5 m/s 8 m ahead reaches the ego's side before the ego is past
    (0.93 s against 1.8 s) and is followed; a slow one turning in 26 m ahead, which the ego reaches
    only after 1.2 s (beyond the 1-s cut-in lookahead, as far as a sideways motion is trusted), is
    followed though it would touch only after the ego is past; one drifting in at 0.5 m/s
    alongside the ego's front, which touches only after the ego is past (2.26 s against 1.68 s)
    though it comes within the side margin before (1.66 s), is passed: braking would hold the ego
    beside it for 2.4 s."""
    car = Actor(EGO_START_S + rel_s, d, speed)
    world = ScriptedRoad(4, 1, 25.0, [car], Stationary(), "kinematic", DT, 5.0).reset()
    world = dataclasses.replace(world, heading=world.heading.copy())
    world.heading[1] = heading
    assert len(leaders(world, (1,), 1.0)) == followed


@pytest.mark.parametrize(("ego_d", "lanes", "followed"), [(3.5, (1, 0), True), (3.5, (0, 1), False)])
def test_a_wreck_reaching_into_the_target_lane_is_judged_from_that_lane_s_centre(ego_d, lanes, followed):
    """A wreck stopped 20 m ahead, its centre at d = 6.61 m turned 0.35 rad towards the lane
    centred at 4 m (its footprint reaches down to 4.87 m): the ego at 25 m/s at d = 3.5 m clears it
    by 0.07 m more than the side margin where it is now, but heading for that lane's centre its
    side comes to 5 m, into the wreck, so it follows it; heading back to the lane centred at 0 m it
    passes it (a development episode: the ego settling into the lane drove into the wreck)."""
    wreck = Actor(EGO_START_S + 20.0, 6.61, 0.0)
    world = ScriptedRoad(4, 1, 25.0, [wreck], Stationary(), "kinematic", DT, 5.0).reset()
    world = dataclasses.replace(world, heading=world.heading.copy(), d=world.d.copy())
    world.heading[1], world.d[0] = -0.348, ego_d
    assert sum(not leader.may_turn_back for leader in leaders(world, lanes, 1.0)) == followed


def test_reference_driver_on_a_lead_braking_point_it_cannot_avoid():
    config = build_config({})
    assert drive_reference(config, Point("lead-braking", (36.11, 0.8, 8.0))).collided


@pytest.fixture
def tiny_grids(monkeypatch):
    monkeypatch.setitem(safety_scenarios.QUICK_GRIDS, "lead-braking", ((20.0,), (1.0,), (3.0, 8.0)))
    monkeypatch.setitem(safety_scenarios.QUICK_GRIDS, "cut-in", ((20.0,), (4.0,), (10.0,), (1.0,)))
    monkeypatch.setitem(safety_scenarios.QUICK_GRIDS, "cut-out", ((20.0,), (40.0,), (2.0,)))


def test_safety_cli_writes_summary_csv_and_maps(tmp_path, tiny_grids):
    out = tmp_path / "safety"
    result = CliRunner().invoke(app, ["safety", "--quick", "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["agent"] == "ddqn" and summary["grid"] == "quick"
    lead = summary["scenarios"]["lead-braking"]
    assert lead["points"] == 2 and lead["failures"] == 0
    rows = (out / "safety.csv").read_text().splitlines()
    assert len(rows) == 1 + 4 and "outcome" in rows[0] and "stack_min_ttc_s" in rows[0]
    for kind in safety_scenarios.SCENARIO_KINDS:
        assert (out / f"safety_{kind}.png").stat().st_size > 10_000
    assert (out / "config.yaml").is_file()


NEVER_BRAKES = [
    "--agent",
    "keep-lane",
    "--set",
    "controller.comfort_decel_mps2=0.01",
    "--set",
    "controller.emergency_decel_mps2=0.01",
    "--set",
    "controller.emergency_ttc_s=0",
]
"""A stack that never brakes (and never changes lane) in CLI options."""


def test_safety_cli_lists_failures_with_a_replay_command_that_writes_a_video(tmp_path, tiny_grids):
    out = tmp_path / "never"
    result = CliRunner().invoke(
        app,
        [
            "safety",
            "--scenario",
            "lead-braking",
            "--quick",
            *NEVER_BRAKES,
            "--out",
            str(out),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    failures = json.loads((out / "summary.json").read_text())["scenarios"]["lead-braking"]["failure_points"]
    assert [(f["speed"], f["deceleration"]) for f in failures] == [(20.0, 3.0)]
    replay = failures[0]["replay"]
    assert replay in result.output.replace("\n", "")
    command = replay.split()[1:] + ["--out", str(tmp_path / "replay")]
    result = CliRunner().invoke(app, command)
    assert result.exit_code == 0, result.output
    assert (tmp_path / "replay" / "safety_lead-braking.gif").stat().st_size > 10_000
    assert json.loads((tmp_path / "replay" / "point.json").read_text())["outcome"] == "failure"


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--point", "speed=20"], "--point: name one --scenario"),
        (["--video"], "--video: replays one point"),
        (["--scenario", "cut-in", "--point", "speed=20,gap=3"], "--point: missing"),
        (["--scenario", "swerve"], "--scenario: unknown 'swerve'"),
        (["--set", "highway.lanes_count=2"], "need 3 or more lanes"),
    ],
)
def test_safety_cli_refuses_bad_input_in_one_line(tmp_path, arguments, message):
    result = CliRunner().invoke(app, ["safety", *arguments, "--out", str(tmp_path / "x")])
    assert result.exit_code == 2 and message in result.output, result.output
    assert not (tmp_path / "x").exists()


def test_a_stop_before_a_scenario_type_has_a_point_keeps_the_others_and_exits_130(
    tmp_path, tiny_grids, monkeypatch
):
    """Issue 52 (8): the stop used to end in 'internal error: ValueError: Number of columns ...'
    while drawing the map of a type without a finished point."""
    from stack.apps import safety as safety_app

    real = safety_app.completed

    def first_then_stop(*arguments, **options):
        yield next(iter(real(*arguments, **options)))
        raise KeyboardInterrupt

    monkeypatch.setattr(safety_app, "completed", first_then_stop)
    out = tmp_path / "safety"
    result = CliRunner().invoke(app, ["safety", "--quick", "--out", str(out), "--no-progress"])
    assert result.exit_code == 130, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] and summary["scenarios"]["lead-braking"]["points"] == 1
    assert summary["scenarios"]["cut-out"]["points"] == 0 and not (out / "safety_cut-out.png").exists()
    assert (out / "safety_lead-braking.png").is_file()


def test_a_car_between_lanes_close_ahead_is_the_cruise_s_leader_but_not_emergency_braking_s():
    """A cut-out car past the ego lane's reach but short of its new lane's wandering zone: 60 m
    ahead it is nobody's leader; 10 m ahead, within the road the ego covers in the 1 s lookahead,
    the cruise keeps its gap to it (it may turn back), while emergency braking waits for it to."""
    road = build(Point("cut-out", (20.0, 60.0, 2.0)), 4, "kinematic", DT)
    world = road.reset()
    while road.actors[0].d < 7.4:
        world = road.step(Actuation(0.0, 0.0))
    mover = int(abs(world.d - road.actors[0].d).argmin())
    assert not any(leader.vehicle == world.ids[mover] for leader in leaders(world, (1,), 1.0))
    s = world.s.copy()
    s[mover] = s[0] + LENGTH + 10.0
    close = dataclasses.replace(world, s=s)
    assert not any(leader.vehicle == world.ids[mover] for leader in leaders(close, (1,), 0.0))
    (held,) = [leader for leader in leaders(close, (1,), 1.0) if leader.vehicle == world.ids[mover]]
    assert held.may_turn_back and held.gap == pytest.approx(10.0)
    stopped_behind_it = Neighbour(held.gap, 0.0, held.vehicle, may_turn_back=False)
    for leader, braked in ((stopped_behind_it, -5.0), (held, 0.0)):
        acted = EmergencyBraking(5.0, 3.0, 1.0).apply(Actuation(0.0, 0.0), 20.0, (leader,), DT)
        assert acted.acceleration == braked


@pytest.mark.parametrize(
    ("ahead_m", "speed", "beyond", "held_gap"),
    [(3.0, 20.0, 3, LENGTH - 3.0), (3.0, 20.0, -1, None), (30.0, 20.0, 3, None), (4.5, 10.0, 3, None)],
)
def test_a_car_beside_the_ego_in_the_lane_beyond_its_target_is_the_cruise_s_leader(
    ahead_m: float, speed: float, beyond: int, held_gap: float | None
) -> None:
    """During a change into lane 2, a car in lane 3 whose centre is `ahead_m` ahead of the ego's at
    `speed` [m/s] (the ego at 20 m/s): beside the ego it may take lane 2 at the same moment, so the
    cruise keeps its gap to it (gap negative: the two overlap) and emergency braking does not fire
    for it; not without a change, not 30 m ahead, not a much slower car the ego is all but past."""
    road = build(Point("cut-out", (20.0, 60.0, 2.0)), 4, "kinematic", DT)
    world = road.reset()
    mover = 1
    s, d, speeds = world.s.copy(), world.d.copy(), world.speed.copy()
    s[mover], d[mover], speeds[mover] = s[0] + ahead_m, safety_scenarios.lane_centre(3), speed
    beside = dataclasses.replace(world, s=s, d=d, speed=speeds)
    found = [
        leader for leader in leaders(beside, (2,), 1.0, beyond=beyond) if leader.vehicle == world.ids[mover]
    ]
    if held_gap is None:
        assert not found
        return
    (held,) = found
    assert held.may_turn_back and held.gap == pytest.approx(-held_gap)
    acted = EmergencyBraking(5.0, 3.0, 1.0).apply(Actuation(0.0, 0.0), 20.0, (held,), DT)
    assert acted.acceleration == 0.0
