"""Many traffic worlds stepped together, with [worlds, vehicles] arrays as the state of record.

Each world is highway-v0 with the stack's traffic (`stack.sim.traffic`) and an ego driven by a given
actuation, the same world the `vector` backend drives alone through `HighwayAdapter`, bit for bit
(or exit-v0's, its through lanes held as one segment with highway-env's per-segment neighbour
search: `stack.sim.batch.through_road`):
at reset highway-env spawns the world's road with the world's own generator (a seed, or the stream
the world's last reset left, as one env's `reset()` continues it), the arrays read it once, and from
then on a frame of every world is a fixed sequence of compiled kernels (`stack.sim.batch.traffic_kernels`,
the vector backend's `dynamics` and `frame.IdmRows`) and numpy's transcendental calls and dot products
over all the worlds' vehicles at once, in highway-env's operation order:

- act: each world's lane coordinates and lane occupancy; every IDM driver's own-lane neighbours,
  its MOBIL candidates (when its timer is due) and abort candidates (while it changes lane); the
  IDM accelerations of all of them in one call; the decisions in road order per world (a driver
  reads the target lanes the ones before it just chose); the target-lane IDM of the drivers
  changing lane and the steering controller;
- step: `clip_actions` (and `TrafficVehicle`'s stop at a standstill), the kinematic bicycle,
  pending impacts, the lane-change timers, the closest lane; the collision candidates
  (`could_touch` along a sweep, a superset) go through highway-env's own `_is_colliding`, pair by pair in
  stock's order, which sets the impacts and crash flags.

The four facts this identity rests on are the vector backend's (`stack.sim.vector.road`). Worlds
whose episode ended (the ego crashed, or the duration is reached) are reset at their next `step`,
which returns their first frame instead of stepping them (gymnasium's next-step autoreset); the
other worlds step on, untouched. `road(world)` builds highway-env's objects on request; the arrays
(`TrafficBatch.arrays`, `stack.sim.batch.arrays`) are the state of record."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.envs.common.action import ContinuousAction
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from common.compiled import Kernel
from records import RoadName
from stack.settings.world import HighwayConfig
from stack.sim.batch.arrays import BatchArrays
from stack.sim.batch.through_road import read_through_road
from stack.sim.batch.traffic_frame import act, in_worlds, move
from stack.sim.batch.world_reading import UnsupportedRoad, read_world, road_of
from stack.sim.fast_road import FastExitEnv, FastRoadNetwork
from stack.sim.highway import MAX_ACCELERATION, MAX_STEERING, env_config, unit_command
from stack.sim.traffic import ScenarioTraffic
from stack.sim.vector.lanes import LaneTable


class SpawningTraffic(ScenarioTraffic):
    """The world a reset spawns (`drivestack/Highway-v0`, `ScenarioTraffic`) on a road network that
    finds each new vehicle's closest lane in plain floats (`FastRoadNetwork`: stock's lane, the
    same bits, without a numpy call per lane), a fifth of a reset's time otherwise."""

    def _create_road(self) -> None:
        super()._create_road()
        self.road.network.__class__ = FastRoadNetwork


SPAWNERS: dict[RoadName, type[AbstractEnv]] = {"highway": SpawningTraffic, "exit": FastExitEnv}
"""The env that spawns a world of each road (exit-v0's the `vector` backend's own: the same draws)."""


@dataclass(frozen=True, eq=False)
class Ended:
    """Per world, after a step: whether its episode ended by the ego's crash (`terminated`) or
    its duration (`truncated`); such a world is reset at its next step."""

    terminated: np.ndarray
    truncated: np.ndarray


def _linear_map(low: float, high: float) -> tuple[float, float, float, float]:
    """highway-env's `utils.lmap(v, [-1, 1], [low, high])` as its operands: x0, y0, the range's
    span y1 - y0 and the domain's x1 - x0, each as `lmap` computes it."""
    x = [-1, 1]
    return float(x[0]), float(low), float(high - low), float(x[1] - x[0])


ACTUATION_MAPS = (
    _linear_map(*ContinuousAction.ACCELERATION_RANGE),
    _linear_map(*ContinuousAction.STEERING_RANGE),
)
"""`ContinuousAction`'s maps from [-1, 1] to acceleration and to steering (`_linear_map`)."""


@Kernel
def drive_egos(
    actuation_out: tuple[np.ndarray, np.ndarray],
    rows: np.ndarray,
    actuation: tuple[np.ndarray, np.ndarray],
    limits: tuple[float, float],
    maps: tuple[tuple[float, float, float, float], tuple[float, float, float, float]],
) -> None:  # pragma: no cover - compiled
    """The egos' acceleration and steering [m/s^2, rad] (`actuation`, one each a row of `rows`)
    into the flat arrays `actuation_out` at `rows`: each normalised to [-1, 1] by its `limits`
    (`stack.sim.highway.unit_command`, `to_env_action`'s law), clipped again and mapped back
    (`ContinuousAction`, highway-env's `lmap`: y0 + (v - x0) * span / domain, `maps`), in numpy's
    operations and order: the same bits as the env's step."""
    for k in range(len(rows)):
        for c in range(2):
            x0, y0, span, domain = maps[c]
            v = unit_command(actuation[c][k], limits[c])
            v = np.minimum(np.maximum(v, -1.0), 1.0)
            actuation_out[c][rows[k]] = y0 + (v - x0) * span / domain


class TrafficBatch:
    """N worlds of one highway config (`HighwayConfig`, kinematic ego), stepped together."""

    def __init__(self, highway: HighwayConfig | Sequence[HighwayConfig], worlds: int) -> None:
        """`worlds` worlds of `highway`, or of the configs `highway` lists (a mix: each world's
        reset names its member; they must share one frame rate)."""
        if worlds < 1:
            raise ValueError(f"a batch needs at least one world, got {worlds}")
        members = [highway] if isinstance(highway, HighwayConfig) else list(highway)
        self.highway = members[0]
        self.worlds = worlds
        self._roads = [member.road for member in members]
        self._spawners = [SPAWNERS[member.road](config=env_config(member)) for member in members]
        configs = [spawner.config for spawner in self._spawners]
        rates = {(config["simulation_frequency"], config["policy_frequency"]) for config in configs}
        if len(rates) != 1:
            raise ValueError("batched worlds share one simulation and policy frequency")
        config = configs[0]
        self.dt = 1 / config["simulation_frequency"]
        self._time_step = 1 / config["policy_frequency"]
        self._durations = [float(config["duration"]) for config in configs]
        if any(config["offroad_terminal"] for config in configs):
            raise ValueError("batched traffic ends an episode on the ego's crash or the duration only")
        self._member = np.zeros(worlds, dtype=np.int64)
        self._duration = np.full(worlds, self._durations[0])
        self._rngs: list[np.random.Generator | None] = [None] * worlds
        self._lane_tables: list[LaneTable | None] = [None] * worlds
        self._networks: list[RoadNetwork | None] = [None] * worlds
        self.arrays = BatchArrays(worlds)
        """The state of record."""
        self.time = np.zeros(worlds)
        """Each world's episode time [s], as the env counts it."""
        self.ended = Ended(np.zeros(worlds, dtype=bool), np.zeros(worlds, dtype=bool))
        self._pending_reset = np.zeros(worlds, dtype=bool)

    def close(self) -> None:
        for spawner in self._spawners:
            spawner.close()

    def reset(self, seeds: Sequence[int]) -> None:
        """Reset every world, world k with `seeds[k]`."""
        if len(seeds) != self.worlds:
            raise ValueError(f"one seed per world: {self.worlds} worlds, {len(seeds)} seeds")
        for world, seed in enumerate(seeds):
            self.reset_world(world, seed)

    def reset_world(self, world: int, seed: int | None = None, member: int | None = None) -> None:
        """Spawn world `world` anew: with `seed`, or (None) with the generator its last reset left;
        as the mix's `member` (an index of the configs given), or as the member it was."""
        if member is not None:
            self._member[world] = member
            self._duration[world] = self._durations[member]
        env = self._spawners[int(self._member[world])]
        if seed is None:
            rng = self._rngs[world]
            if rng is None:
                raise ValueError(f"world {world} has no generator yet: reset it with a seed first")
            env._np_random = rng
        env.reset(seed=seed)
        self._rngs[world] = env.np_random
        if type(env.vehicle) is not Vehicle:
            raise ValueError("batched traffic drives a kinematic ego (plant: kinematic)")
        if self._roads[int(self._member[world])] == "exit":
            spawned = read_through_road(env.road, env.vehicle, int(env.config["lanes_count"]))
        else:
            spawned = read_world(env.road, env.vehicle)
        self.arrays.load(world, spawned)
        self._lane_tables[world], self._networks[world] = spawned.lanes, spawned.network
        self.time[world] = env.time
        self.ended.terminated[world] = self.ended.truncated[world] = False
        self._pending_reset[world] = False

    def load_worlds(
        self, worlds: Sequence[int], road: Road, ego: Vehicle, time: float, acts: int, member: int = 0
    ) -> None:
        """Each world of `worlds` set to a road some env drives alone, as it stands `time` [s] into
        its episode (copies to play its futures on: `road` is only read): its vehicles, lanes and
        ego read into the arrays, its sudden brakings' clock at `acts` frames, as the mix's
        `member`. `UnsupportedRoad` for a road the arrays cannot hold, or with a driver who acts on
        a delayed view (the arrays would need the past it saw)."""
        spawned = read_world(road, ego)
        if spawned.columns["delay_frames"].any():
            raise UnsupportedRoad("a copied world holds no driver acting on a delayed view")
        for world in worlds:
            self._member[world], self._duration[world] = member, self._durations[member]
            self.arrays.load(world, spawned)
            self.arrays.acts[world] = acts
            self._rngs[world] = road.np_random
            self._lane_tables[world], self._networks[world] = spawned.lanes, spawned.network
            self.time[world] = time
            self.ended.terminated[world] = self.ended.truncated[world] = False
            self._pending_reset[world] = False

    def step(
        self, acceleration: npt.ArrayLike, steering: npt.ArrayLike, only: np.ndarray | None = None
    ) -> Ended:
        """One frame of every world, the ego of world k actuated with `acceleration[k]` [m/s^2] and
        `steering[k]` [rad] (through `ContinuousAction`'s normalised range, as `HighwayAdapter`
        applies an `Actuation`: +-5 m/s^2, +-pi/4 rad at most). Worlds that ended at the last step
        are reset instead (their actuation is ignored). With `only` (a flag per world), just those
        worlds step and none is reset: the others stay as they are (a caller that resets ended
        worlds itself)."""
        accelerations, steerings = self._per_world(acceleration), self._per_world(steering)
        unset = [world for world, rng in enumerate(self._rngs) if rng is None]
        if unset:
            raise ValueError(f"worlds {unset} have not been reset: call reset(seeds) first")
        if only is None:
            resetting = self._pending_reset.nonzero()[0]
            for world in resetting.tolist():
                self.reset_world(world)
            stepping = np.ones(self.worlds, dtype=bool)
            stepping[resetting] = False
        else:
            stepping = np.asarray(only, dtype=bool)
            if (stepping & self._pending_reset).any():
                ended = np.flatnonzero(stepping & self._pending_reset).tolist()
                raise ValueError(f"worlds {ended} ended their episode: reset them before stepping")
        arrays, worlds = self.arrays, np.arange(self.worlds)
        active = np.where(stepping, arrays.count, 0)
        self.time[stepping] += self._time_step
        ego_rows = worlds * arrays.vehicles + arrays.ego
        self._drive_egos(ego_rows[stepping], accelerations[stepping], steerings[stepping])
        in_world = in_worlds(arrays, active)
        act(arrays, active, in_world)
        move(arrays, active, in_world, self.dt)
        ego_crashed = arrays.crashed.reshape(-1)[ego_rows]
        terminated = stepping & ego_crashed
        truncated = stepping & (self.time >= self._duration)
        self.ended = Ended(terminated, truncated)
        self._pending_reset = self._pending_reset & ~stepping | terminated | truncated
        return self.ended

    def _per_world(self, values: npt.ArrayLike) -> np.ndarray:
        """`values` as floats, one per world; ValueError for another shape."""
        array = np.asarray(values, dtype=float)
        if array.shape != (self.worlds,):
            raise ValueError(f"one value per world: {self.worlds} worlds, got shape {array.shape}")
        return array

    def _drive_egos(self, rows: np.ndarray, acceleration: np.ndarray, steering: np.ndarray) -> None:
        """`HighwayAdapter.step`'s actuation on the egos: normalised by `to_env_action`, then mapped
        back by `ContinuousAction` (the same float operations, `drive_egos`)."""
        actuation_out = (self.arrays.acceleration.reshape(-1), self.arrays.steering.reshape(-1))
        limits = (float(MAX_ACCELERATION), float(MAX_STEERING))
        drive_egos(actuation_out, rows, (acceleration, steering), limits, ACTUATION_MAPS)

    def road(self, world: int) -> tuple[list[Vehicle], Vehicle]:
        """highway-env objects of world `world` as it stands: its vehicles on a new `Road` of its
        lanes (road order), and its ego (for rendering, video, a user reading the road)."""
        table, network, rng = self._lane_tables[world], self._networks[world], self._rngs[world]
        if table is None or network is None or rng is None:
            raise ValueError(f"world {world} has not been reset")
        arrays = self.arrays
        n = int(arrays.count[world])
        columns = {name: column[world, :n] for name, column in arrays.columns.items()}
        vehicles = road_of(columns, table, network, rng)
        return vehicles, vehicles[int(arrays.ego[world])]
