"""The exit road (exit-v0, `stack.sim.traffic.ExitTraffic`) as batched worlds hold it: its through
lanes as one segment.

exit-v0's network is three straight segments of `lanes_count` lanes end to end (0-400 m, 400-500 m
with one more lane on the right, 500-1000 m) and a curved exit branching off at 500 m. Its traffic
keeps its lane (lane changes off, each car routed to the road's end), spawned in lanes 1 and up;
the stack's ego drives the through lanes only (its snapshot's lanes, `stack.sim.highway.snapshot`).
Along the through lanes the segments continue each other (one centre line, width and speed limit
per lane id), so the batch holds lane k of every segment as one straight lane from the road's
start to its end (`through_road`) and runs the highway road's kernels on it, with what the
segments still change kept as each world's segments (`SpawnedWorld.segment_start`, `segment_length`):

- highway-env's neighbour search counts a car's leaders on its own segment's lane only, up to 5 m
  (`StraightLane.VEHICLE_LENGTH`) past that segment's end, so a car before 400 m or 500 m is blind
  to a leader further past the boundary (`segment_kernels.segment_of`, `_neighbours`); from 2.5 m
  before the end its route has switched its target lane to the next segment's, whose leader it
  heeds as well (`segment_kernels.crossing_drivers`);
- the snapshot measures s from lane 0 of the ego's segment (`BatchArrays.origins`).

Each world is then the one the `vector` backend drives alone (highway-env's own road objects:
`stack.sim.fast_road.FastExitEnv`), bit for bit (`tests/test_sim_batched.py`). The exit lane
(400-500 m) and the curve are not held: no car of the stack's world drives onto them (an ego there
has left the through lanes, a road departure), and a vehicle read on them is refused
(`UnsupportedRoad`)."""

from __future__ import annotations

import numpy as np
from highway_env.road.lane import StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from stack.sim.batch.world_reading import SpawnedWorld, UnsupportedRoad, read_vehicles
from stack.sim.fast_road import LaneIndex
from stack.sim.vector.lanes import LaneTable

FIRST_NODE = "0"
"""The node the road starts at (exit-v0's, as every `straight_road_network`'s)."""


def through_segments(network: RoadNetwork, lanes_count: int) -> list[tuple[str, str]]:
    """The segments (from node, to node) of `network` that chain from `FIRST_NODE`, each the one
    way on from the last whose first `lanes_count` lanes are straight and continue the last's
    (start at its end, same direction, width and speed limit); `UnsupportedRoad` for a fork of
    two such ways or a first segment of fewer lanes."""
    graph = network.graph
    chain: list[tuple[str, str]] = []
    node = FIRST_NODE
    while node in graph:
        ways = [to for to in graph[node] if _continues(network, chain, (node, to), lanes_count)]
        if not ways:
            break
        if len(ways) > 1:
            raise UnsupportedRoad(f"batched worlds need one through road; node {node!r} forks into {ways}")
        chain.append((node, ways[0]))
        node = ways[0]
        if len(chain) > len(graph):
            raise UnsupportedRoad("batched worlds need a through road without a loop")
    if not chain:
        raise UnsupportedRoad(f"batched worlds need {lanes_count} straight lanes from node {FIRST_NODE!r}")
    return chain


def _continues(
    network: RoadNetwork, chain: list[tuple[str, str]], segment: tuple[str, str], count: int
) -> bool:
    """Whether `segment`'s first `count` lanes are straight and, after `chain`'s last segment, start
    where its lanes end, in the same direction, width and speed limit."""
    lanes = network.graph[segment[0]][segment[1]]
    if len(lanes) < count or any(type(lane) is not StraightLane for lane in lanes[:count]):
        return False
    if not chain:
        return True
    before = network.graph[chain[-1][0]][chain[-1][1]]
    return all(
        np.array_equal(lane.start, last.end)
        and np.array_equal(lane.direction, last.direction)
        and lane.width == last.width
        and lane.speed_limit == last.speed_limit
        for lane, last in zip(lanes[:count], before[:count], strict=False)
    )


def through_road(network: RoadNetwork, segments: list[tuple[str, str]], lanes_count: int) -> RoadNetwork:
    """One segment (the first segment's from node to the last's to node) of `lanes_count` straight
    lanes: lane k from lane k's start on the first of `segments` to its end on the last, with the
    first's width, line types, speed limit and whether changing into it is forbidden."""
    first = network.graph[segments[0][0]][segments[0][1]]
    last = network.graph[segments[-1][0]][segments[-1][1]]
    road = RoadNetwork()
    for start, end in zip(first[:lanes_count], last[:lanes_count], strict=True):
        road.add_lane(
            segments[0][0],
            segments[-1][1],
            StraightLane(
                start.start,
                end.end,
                width=start.width,
                line_types=start.line_types,
                forbidden=start.forbidden,
                speed_limit=start.speed_limit,
            ),
        )
    return road


def read_through_road(road: Road, ego: Vehicle, lanes_count: int) -> SpawnedWorld:
    """The arrays of exit-v0's `road` on its through road (`through_road`): each vehicle on lane k of
    one of its segments on lane k; lane-keeping cars routed along it. `UnsupportedRoad` for a road
    without one, or a vehicle on another lane (the exit lane, the curve)."""
    segments = through_segments(road.network, lanes_count)
    network = through_road(road.network, segments, lanes_count)
    lanes = LaneTable.fit(network)
    if lanes is None:
        raise UnsupportedRoad("batched worlds need a through road of parallel, axis-aligned straight lanes")
    held = set(segments)

    def row_of(index: LaneIndex) -> int:
        if index[:2] not in held or not 0 <= index[2] < lanes_count:
            raise UnsupportedRoad(f"batched worlds hold the through road's lanes, not lane {index}")
        return int(index[2])

    reference = network.graph[segments[0][0]][segments[-1][1]][0]
    starts, lengths = [], []
    for origin, end in segments:
        lane = road.network.graph[origin][end][0]
        starts.append(float(np.dot(lane.start - reference.start, reference.direction)))
        lengths.append(float(lane.length))
    return read_vehicles(
        road, ego, lanes, network, row_of, routed=True, segments=(np.array(starts), np.array(lengths))
    )
