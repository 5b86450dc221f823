"""Collision fault as UN R157 decides preventability (`stack.fault.preventability`) and emergency braking's
cause (`stack.fault.emergency_causes`), on constructed scenes of the scripted road: an inattentive
ego (constant speed, or steering into the next lane) meets scripted vehicles, and R157's reference
driver, replayed in its place over the last seconds, decides whether the contact was avoidable."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from records import Actuation, WorldState
from stack.assessment.safety_assessment import plant_for, point_config
from stack.fault.emergency_causes import (
    CAUSES,
    CLOSING_IN,
    CUT_IN,
    LEADER_BRAKING,
    NEVER,
    OWN_LANE_CHANGE,
    PHANTOM,
    emergency_cause,
)
from stack.fault.preventability import judge, touches
from stack.fault.reference_driver import TrafficCarefulDriver
from stack.loop.closed_loop import ClosedLoop
from stack.loop.safety_metrics import SafetyMeasures, SafetyMonitor
from stack.runs.alone import run_agent_episode
from stack.runs.kept import build_agent
from stack.settings.run import build_config
from stack.sim.safety_scenarios import EGO_LANE, LENGTH, lane_centre, parse_point
from stack.sim.scripted_road import EGO_START_S, Actor, ScriptedRoad

SPEED = 25.0
"""The ego's and the actors' speed at the start [m/s]."""
DT = 1 / 15


class Timed:
    """At `move_at` [s] actor 0 heads for `to_lane` at `lateral_speed` [m/s]; at `brake_at` [s] it
    brakes at `braking` [m/s^2] (None: never)."""

    def __init__(
        self,
        move_at: float | None = None,
        to_lane: int = EGO_LANE,
        lateral_speed: float = 1.5,
        brake_at: float | None = None,
        braking: float = 0.0,
    ) -> None:
        self.move_at, self.to_lane, self.lateral_speed = move_at, to_lane, lateral_speed
        self.brake_at, self.braking = brake_at, braking

    def update(self, time: float, ego_s: float, actors: list[Actor]) -> None:
        actor = actors[0]
        if self.move_at is not None and time >= self.move_at - 1e-9 and actor.target_d is None:
            actor.target_d, actor.lateral_speed = lane_centre(self.to_lane), self.lateral_speed
        if self.brake_at is not None and time >= self.brake_at - 1e-9:
            actor.braking = self.braking

    def settled(self, actors: list[Actor]) -> bool:
        return False


class Moves:
    """At each `(time [s], actor, lane)` of `moves` that actor heads for `lane` at 3 m/s sideways."""

    def __init__(self, *moves: tuple[float, int, int]) -> None:
        self.moves = moves

    def update(self, time: float, ego_s: float, actors: list[Actor]) -> None:
        for move_at, index, lane in self.moves:
            actor = actors[index]
            if time >= move_at - 1e-9 and actor.target_d is None:
                actor.target_d, actor.lateral_speed = lane_centre(lane), 3.0

    def settled(self, actors: list[Actor]) -> bool:
        return False


def drive(
    actors: list[Actor],
    script: Timed | Moves,
    steering: float = 0.0,
    seconds: float = 15.0,
    acceleration: float = 0.0,
    lanes: int = 3,
) -> SafetyMeasures:
    """The inattentive ego (`acceleration` [m/s^2], no brake, `steering` [rad]) on the scripted
    road of `lanes` lanes until it collides: what the safety monitor measured, judging the contact."""
    road = ScriptedRoad(lanes, EGO_LANE, SPEED, actors, script, "kinematic", DT, seconds)
    monitor = SafetyMonitor(DT)
    monitor.start(road.reset())
    while not road.done:
        monitor.record(road.step(Actuation(acceleration=acceleration, steering=steering)), steering != 0.0)
    assert road.crashed
    return monitor.measured()


def ahead(gap: float, lane: int = EGO_LANE, speed: float = SPEED) -> Actor:
    """An actor whose rear is `gap` [m] ahead of the ego's front, in `lane`."""
    return Actor(EGO_START_S + LENGTH + gap, lane_centre(lane), speed)


def test_a_car_cutting_in_5_m_ahead_and_braking_is_not_the_ego_s_fault() -> None:
    measured = drive([ahead(5.0, EGO_LANE + 1)], Timed(move_at=0.5, brake_at=1.5, braking=5.0))
    assert measured.collision_kind == "front"
    assert not measured.at_fault_collision
    assert measured.fault_reason == "cut-in not preventable"


def test_a_cut_out_far_ahead_does_not_let_the_reference_brake_sooner_for_a_later_cut_in() -> None:
    """A car 60 m ahead leaves the ego's lane at 0.3 s; 2 s later a car 5 m/s slower and 5 m ahead
    cuts in.
    R157's driver reacts to each vehicle's risk after its own 1.15 s: the earlier, unrelated risk
    does not start its braking for the cut-in sooner, so the contact was not preventable."""
    far, cutting = ahead(60.0, speed=20.0), ahead(16.7, EGO_LANE + 1, speed=20.0)
    measured = drive([far, cutting], Moves((0.3, 0, EGO_LANE + 1), (2.3, 1, EGO_LANE)))
    assert measured.collision_kind == "front"
    assert measured.fault_reason == "cut-in not preventable"


def test_a_lane_change_far_down_the_road_is_no_risk_to_the_reference_driver() -> None:
    road = ScriptedRoad(
        3, EGO_LANE, SPEED, [ahead(400.0, EGO_LANE + 1)], Moves((0.0, 0, EGO_LANE)), "kinematic", DT, 5.0
    )
    world, driver = road.reset(), TrafficCarefulDriver()
    while not road.done:
        assert driver.step(world, DT).acceleration == 0.0
        world = road.step(Actuation(0.0, 0.0))
    assert driver.risks == {}


def test_the_reference_drives_as_the_ego_drove_until_it_reacts() -> None:
    """The ego speeds up at 1.5 m/s^2 beside a car 20 m ahead in the next lane at its own start
    speed, which cuts in once the ego is 12 m nearer: a reference that had held its start speed
    would never have met it, one that drove as the ego did until R157's reaction meets it."""
    measured = drive([ahead(20.0, EGO_LANE + 1)], Moves((4.0, 0, EGO_LANE)), acceleration=1.5)
    assert measured.collision_kind == "front"
    assert measured.fault_reason == "cut-in not preventable"


@pytest.mark.parametrize(
    ("crossed_s", "settled_s", "reason"),
    [
        (0.3, 0.3, "cut-in not preventable"),
        (0.3, 1.0, "cut-in not preventable"),
        (1.0, 1.0, "own lane change"),
    ],
)
def test_a_cut_in_after_the_ego_entered_its_new_lane_is_judged_by_the_replay(
    crossed_s: float, settled_s: float, reason: str
) -> None:
    """The contact of `test_a_car_cutting_in_5_m_ahead_and_braking...` (the cut-in starts at 0.5 s),
    its frames rewritten as if the ego had come from the next lane, its centre crossing into the new
    lane at `crossed_s` and settling (within the wandering zone) at `settled_s`: a cut-in that began
    after the ego's centre was in the new lane, settled or not, is judged by the replay; one that
    began while it was still in the lane it left is its own lane change."""
    road = ScriptedRoad(
        3,
        EGO_LANE,
        SPEED,
        [ahead(5.0, EGO_LANE + 1)],
        Timed(0.5, brake_at=1.5, braking=5.0),
        "kinematic",
        DT,
        15.0,
    )
    monitor = SafetyMonitor(DT)
    world = road.reset()
    frames = [world]
    while not road.crashed:
        world = road.step(Actuation(0.0, 0.0))
        frames.append(world)
    monitor.start(frames[0])
    for frame in frames[1:]:
        monitor.record(frame, False)
    assert monitor.collision is not None
    came_from = lane_centre(EGO_LANE - 1)

    def changing(frame: WorldState) -> WorldState:
        if frame.time >= settled_s:
            return frame
        lane, d = frame.lane.copy(), frame.d.copy()
        crossed = frame.time >= crossed_s
        lane[0] = EGO_LANE if crossed else EGO_LANE - 1
        d[0] = came_from + (0.7 if crossed else 0.4) * (d[0] - came_from)
        return replace(frame, lane=lane, d=d)

    fault = judge(monitor.collision.kind, monitor.collision.other, [changing(f) for f in frames[-76:]], DT)
    assert fault.reason == reason and fault.at_fault == (reason == "own lane change")


def test_the_ego_changing_lane_into_a_car_is_at_fault() -> None:
    beside = Actor(EGO_START_S, lane_centre(EGO_LANE + 1), SPEED)
    measured = drive([beside], Timed(), steering=0.03)
    assert measured.collision_kind == "lane change"
    assert measured.at_fault_collision and measured.fault_reason == "own lane change"


def test_running_into_a_car_braking_at_3_mps2_from_a_safe_gap_is_at_fault() -> None:
    safe_gap = 1.6 * SPEED
    measured = drive([ahead(safe_gap)], Timed(brake_at=1.0, braking=3.0))
    assert measured.collision_kind == "front"
    assert measured.at_fault_collision
    assert measured.fault_reason == "leader braking preventable"


def test_driving_up_to_a_slower_car_is_at_fault() -> None:
    measured = drive([ahead(60.0, speed=15.0)], Timed())
    assert measured.at_fault_collision and measured.fault_reason == "closing in preventable"


def test_a_leader_braking_hard_within_the_reaction_time_is_not_preventable() -> None:
    measured = drive([ahead(8.0)], Timed(brake_at=1.0, braking=6.0))
    assert not measured.at_fault_collision
    assert measured.fault_reason == "leader braking not preventable"


@pytest.mark.parametrize(
    ("phantom", "drifted_at", "braked_at", "ego_changed_at", "cause"),
    [
        (True, 9.0, 9.0, 9.0, PHANTOM),
        (False, 9.0, 9.5, 9.5, CUT_IN),
        (False, 7.0, 9.5, 9.5, LEADER_BRAKING),
        (False, NEVER, 7.9, 8.0, OWN_LANE_CHANGE),
        (False, 7.9, 7.9, 7.9, CLOSING_IN),
        (False, NEVER, NEVER, NEVER, CLOSING_IN),
    ],
)
def test_an_emergency_braking_s_cause_is_the_first_that_holds(
    phantom: bool, drifted_at: float, braked_at: float, ego_changed_at: float, cause: int
) -> None:
    """At 10 s, events within the last 2 s count: phantom, then cut-in, leader braking, own lane
    change, else closing in."""
    assert emergency_cause(phantom, 10.0, drifted_at, braked_at, ego_changed_at, 2.0) == cause
    assert math.isinf(NEVER)


@pytest.mark.parametrize(
    ("kind", "point", "cause"),
    [
        ("lead-braking", "speed=25,time_gap=1.0,deceleration=6", "leader_braking"),
        ("cut-in", "speed=25,gap=4,relative_speed=6,lateral_speed=3", "cut_in"),
    ],
)
def test_the_stack_s_emergency_braking_is_counted_by_its_cause(kind: str, point: str, cause: str) -> None:
    """The full stack on a safety-assessment point: each activation counted once, by its cause."""
    config = point_config(build_config({}, "test", planner__agent="keep-lane"), parse_point(kind, point))
    agent = build_agent(config, config.seed)
    loop = ClosedLoop(config, plant_for(config, parse_point(kind, point)), grid=agent.grid_config)
    result = run_agent_episode(loop, agent, 0, config.seed)
    by_cause = {name: getattr(result, f"emergency_brakings_{name}") for name in CAUSES}
    assert result.emergency_brakings >= 1 and by_cause[cause] == result.emergency_brakings, by_cause


def test_a_braking_for_a_track_is_the_true_vehicle_s_under_it_and_a_phantom_s_only_when_none_is():
    """Tracks carry the tracker's own ids: the cause is read from the true vehicle nearest the track,
    within 3 m along and 1.5 m across the road."""
    import numpy as np

    from stack.fault.emergency_causes import true_row

    truth_s, truth_d = np.array([0.0, 30.0, 60.0]), np.array([4.0, 4.0, 8.0])
    assert true_row(31.2, 4.5, truth_s, truth_d) == 1
    assert true_row(59.0, 7.0, truth_s, truth_d) == 2
    assert true_row(45.0, 4.0, truth_s, truth_d) == -1
    assert true_row(0.5, 4.0, truth_s, truth_d) == -1, "the ego is never the vehicle braked for"


def test_being_hit_from_behind_or_standing_while_keeping_the_lane_is_the_other_s():
    """The follower's recorded path answered the ego's own braking: no replay can judge it."""
    from stack.fault.preventability import judge
    from tests.helpers import scene

    world = scene(3, (0.0, 1), [(-6.0, 4.0)], speed=10.0, other_speed=20.0)
    for kind in ("rear", "ego stopped"):
        fault = judge(kind, 1, [world, world], 1 / 15)
        assert not fault.at_fault and fault.reason == f"{kind} not preventable"
    assert judge("lane change", 1, [world], 1 / 15).at_fault


@pytest.mark.parametrize(("heading", "meets"), [(-0.2, True), (0.0, False)])
def test_a_contact_is_what_the_simulation_counts_a_crash(heading: float, meets: bool) -> None:
    """highway-env marks a crash when two footprints meet within the next tick at their velocities
    (and pushes them apart, so the recorded crash frame may show a gap): a car 0.2 m beside the
    ego's side and turned 0.2 rad towards it (5 m/s sideways) is a contact; one driving straight
    is not."""
    road = ScriptedRoad(3, EGO_LANE, SPEED, [ahead(-3.0, EGO_LANE + 1)], Timed(), "kinematic", DT, 5.0)
    world = road.reset()
    d, turned = world.d.copy(), world.heading.copy()
    d[1], turned[1] = d[0] + world.width[0] / 2 + world.width[1] / 2 + 0.2, heading
    assert touches(replace(world, d=d, heading=turned), False, DT) == meets


@pytest.mark.parametrize(("cutting_in", "at_fault"), [(False, True), (True, False)])
def test_a_car_crossing_into_the_lane_the_ego_leaves_is_replayed(cutting_in: bool, at_fault: bool) -> None:
    """The ego drifts out of its lane away from a car alongside in the next lane: when that car cuts
    into the lane the ego is leaving and meets it, the contact is replayed (a careful driver could
    not have braked out of it: not at fault); when the ego instead drifts towards a car alongside,
    its lane change is at fault."""
    beside = Actor(EGO_START_S, lane_centre(EGO_LANE + (1 if cutting_in else -1)), SPEED)
    script = Moves((0.5, 0, EGO_LANE)) if cutting_in else Timed()
    measured = drive([beside], script, steering=-0.002 if cutting_in else -0.03)
    assert measured.collision_kind == "lane change"
    assert measured.at_fault_collision == at_fault
    assert measured.fault_reason == ("own lane change" if at_fault else "cut-in not preventable")


@pytest.mark.parametrize(("moves_at", "at_fault"), [(3.0, True), (4.5, False)])
def test_a_car_entering_the_lane_the_ego_has_entered_from_the_far_side_is_replayed(
    moves_at: float, at_fault: bool
) -> None:
    """The ego drifts from lane 1 towards lane 2 of four, its centre crossing into lane 2 after
    about 4 s; a car alongside in lane 3 heads for lane 2 at 3 m/s sideways at `moves_at`. Both
    entering lane 2 at once (the car moved first) is the ego's lane change, at fault; the car
    entering once the ego's centre was in lane 2 cut into a lane the ego was already in: the
    contact is replayed, and a careful driver could not have braked out of it either."""
    beside = Actor(EGO_START_S + 2.0, lane_centre(EGO_LANE + 2), SPEED)
    measured = drive([beside], Moves((moves_at, 0, EGO_LANE + 1)), steering=0.002, lanes=4)
    assert measured.collision_kind == "lane change"
    assert measured.at_fault_collision == at_fault
    assert measured.fault_reason == ("own lane change" if at_fault else "cut-in not preventable")
