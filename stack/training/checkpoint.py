"""What a training checkpoint's metadata holds, as typed records with JSON round-trips: the
counters SB3 (or the tabular learner) schedules by, the generators, each env's episode under way,
the validation state and the time trained. The JSON keys are those of every checkpoint written so
far: one written before resume was exact (no generators, no episodes) reads with those as None
and resumes with fresh episodes."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Generic, TypeVar

import numpy as np

from records import N_ACTIONS
from stack.training.decision_env import EpisodeRecord

MAX_EPISODE_DECISIONS = 100_000
"""Most actions an episode record of a checkpoint may hold (an hour of driving at 25 per second)."""


@dataclass(frozen=True, kw_only=True)
class DqnCounters:
    """A (Double) DQN run's counters: SB3's steps, updates, calls and episodes, the exploration
    rate, the replay buffer's position, the optimizer's parameter groups, numpy's global generator
    (`numpy_random`: position, gauss flag, cached gauss; its keys are an array of the file), the
    action space's generator, each env's episode under way and the gradient steps put off to the
    next step (`train.overlap`)."""

    num_timesteps: int
    n_updates: int
    n_calls: int | None = None
    episode_num: int
    exploration_rate: float | None = None
    buffer_pos: int
    buffer_full: bool
    param_groups: list[dict[str, Any]]
    numpy_random: tuple[int, int, float] | None = None
    action_space_random: dict[str, Any] | None = None
    episodes: tuple[EpisodeRecord, ...] | None = None
    pending_gradient_steps: int | None = None

    def to_json(self) -> dict[str, Any]:
        return _without_none(
            {
                "num_timesteps": self.num_timesteps,
                "n_updates": self.n_updates,
                "n_calls": self.n_calls,
                "episode_num": self.episode_num,
                "exploration_rate": self.exploration_rate,
                "buffer_pos": self.buffer_pos,
                "buffer_full": self.buffer_full,
                "param_groups": self.param_groups,
                "numpy_random": list(self.numpy_random) if self.numpy_random is not None else None,
                "action_space_random": self.action_space_random,
                "episodes": _episodes_json(self.episodes),
                "pending_gradient_steps": self.pending_gradient_steps,
            }
        )

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> DqnCounters:
        """KeyError / TypeError / ValueError for counters that are not these."""
        numpy_random = data.get("numpy_random")
        if numpy_random is not None:
            position, has_gauss, gauss = numpy_random
            numpy_random = (_int(position), _int(has_gauss), _number(gauss))
        param_groups = data["param_groups"]
        if not isinstance(param_groups, list) or not all(isinstance(g, dict) for g in param_groups):
            raise TypeError("param_groups is not a list of objects")
        exploration_rate = data.get("exploration_rate")
        pending = data.get("pending_gradient_steps")
        return cls(
            num_timesteps=_int(data["num_timesteps"]),
            n_updates=_int(data["n_updates"]),
            n_calls=_int(data["n_calls"]) if "n_calls" in data else None,
            episode_num=_int(data["episode_num"]),
            exploration_rate=None if exploration_rate is None else _number(exploration_rate),
            buffer_pos=_int(data["buffer_pos"]),
            buffer_full=bool(data["buffer_full"]),
            param_groups=param_groups,
            numpy_random=numpy_random,
            action_space_random=_generator(data.get("action_space_random")),
            episodes=_episodes(data.get("episodes")),
            pending_gradient_steps=None if pending is None else _count(pending),
        )


@dataclass(frozen=True, kw_only=True)
class TabularCounters:
    """A tabular run's steps, its learner's generator and its episode under way."""

    num_timesteps: int
    tabular_random: dict[str, Any] | None = None
    episodes: tuple[EpisodeRecord, ...] | None = None

    def to_json(self) -> dict[str, Any]:
        return _without_none(
            {
                "num_timesteps": self.num_timesteps,
                "tabular_random": self.tabular_random,
                "episodes": _episodes_json(self.episodes),
            }
        )

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TabularCounters:
        """KeyError / TypeError / ValueError for counters that are not these."""
        return cls(
            num_timesteps=_int(data["num_timesteps"]),
            tabular_random=_generator(data.get("tabular_random")),
            episodes=_episodes(data.get("episodes")),
        )


Counters = TypeVar("Counters", DqnCounters, TabularCounters)


@dataclass(frozen=True)
class Checkpoint(Generic[Counters]):
    """A checkpoint's metadata: its counters, the validation state (`RealTimeValidation.state`)
    and the time trained so far [s]."""

    counters: Counters
    validation: dict[str, Any]
    elapsed_s: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {
            "kind": "checkpoint",
            "counters": self.counters.to_json(),
            "validation": self.validation,
            "elapsed_s": self.elapsed_s,
        }


def read_checkpoint(data: dict[str, Any], counters: type[Counters]) -> Checkpoint[Counters]:
    """The checkpoint `data` (a checkpoint file's metadata) describes, its counters read as
    `counters`; KeyError / TypeError / ValueError when they are not."""
    validation = data["validation"]
    if not isinstance(validation, dict):
        raise TypeError("its validation state is not an object")
    return Checkpoint(counters.from_json(data["counters"]), validation, _number(data.get("elapsed_s", 0.0)))


def checkpoint_steps(data: dict[str, Any]) -> int:
    """The environment steps a checkpoint's metadata says were done (KeyError / TypeError /
    ValueError when it does not say), read without the rest of its counters."""
    return _int(data["counters"]["num_timesteps"])


def episode_record(data: object) -> EpisodeRecord:
    """An `EpisodeRecord` from a checkpoint's JSON, checked (ValueError / TypeError otherwise)."""
    if not isinstance(data, dict) or set(data) != {"generator_state", "actions"}:
        raise ValueError("an episode record is not {generator_state, actions}")
    actions = data["actions"]
    if (
        not isinstance(actions, list)
        or len(actions) > MAX_EPISODE_DECISIONS
        or not all(type(a) is int and 0 <= a < N_ACTIONS for a in actions)
    ):
        raise ValueError(f"episode actions are not a list of integers in [0, {N_ACTIONS})")
    return EpisodeRecord(generator_state(data["generator_state"]), actions)


def generator_state(state: dict[str, Any]) -> dict[str, Any]:
    """`state` once a PCG64 generator accepts it (ValueError / TypeError otherwise): checked here,
    before it reaches an env worker, where a bad one would end the process."""
    np.random.Generator(np.random.PCG64()).bit_generator.state = state
    return state


def _episodes(data: object) -> tuple[EpisodeRecord, ...] | None:
    if data is None:
        return None
    if not isinstance(data, list):
        raise TypeError("episodes is not a list")
    return tuple(episode_record(entry) for entry in data)


def _episodes_json(episodes: tuple[EpisodeRecord, ...] | None) -> list[dict[str, Any]] | None:
    return None if episodes is None else [asdict(record) for record in episodes]


def _generator(data: object) -> dict[str, Any] | None:
    if data is None:
        return None
    if not isinstance(data, dict):
        raise TypeError("a generator state is not an object")
    return data


def _int(value: object) -> int:
    if not isinstance(value, int):
        raise TypeError(f"expected an integer, got {type(value).__name__}")
    return value


def _count(value: object) -> int:
    count = _int(value)
    if count < 0:
        raise ValueError(f"expected a count, got {count}")
    return count


def _number(value: object) -> float:
    if not isinstance(value, int | float):
        raise TypeError(f"expected a number, got {type(value).__name__}")
    return float(value)


def _without_none(data: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in data.items() if value is not None}
