"""An expert's demonstrations for DQfD-style training (`train.demonstrations`): recorded in the
decision MDP the learner trains in (in the worlds of `train.demonstrations.scenarios` when it names
some), on training seeds of their own stream, spread over processes: as batches of worlds
(`DecisionBatch`, every expert deciding on what the batch perceives, the lookahead for all its
worlds in one call) when every expert and world allows, else one world at a time; the same
episodes either way."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import partial

import numpy as np
from gymnasium.utils import seeding
from tqdm import tqdm

from perception.grid import BATCHED_FEATURES, OccupancyGridBuilder, observe_batch
from planner.agents import Agent, decide, sees_permitted
from planner.ddqn import Demonstrations, DoubleDQN
from planner.factory import make_agent
from planner.validation import RealTimeValidation
from records import N_ACTIONS, Command, GridConfig, child_seed
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import ClosedLoop
from stack.runs.batch_episodes import batches, decide_worlds, decision_grid
from stack.runs.kept import lookahead_setup
from stack.runs.model_fit import checked_expert_model
from stack.runtime.executors import completed
from stack.settings.run import RunConfig, demonstration_worlds, grid_config, training_worlds
from stack.settings.train import LEARNED_EXPERTS, DemonstrationConfig
from stack.training.decision_batch import BatchRefused, DecisionBatch
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.envs import StopTraining
from stack.training.summary import DemonstrationsUsed


def expert_policy(
    world: RunConfig, expert_name: str, model: str | None = None
) -> Callable[[ClosedLoop], int]:
    """The expert, built once for a loop of `world`, as a function of the loop's state to its
    decision: the oracle plans on copies of the loop (whose rollouts perceive on its base agent's
    grid), a policy decides on its own view of what the controllers act on (the sensor's report);
    a learned expert with the Q-network of `model` (by default its shipped file)."""
    lanes, grid = world.highway.lanes_count, grid_config(world)
    if expert_name == "oracle":
        oracle = Oracle.for_road(world.planner.oracle, lanes, grid)
        return lambda loop: oracle.plan(loop).value
    expert = expert_agent(world, expert_name, model)
    view, masked = OccupancyGridBuilder(expert.grid_config or grid), sees_permitted(expert)
    return lambda loop: (
        decide(expert, loop.observation(view.build(loop.perceived), expert.encoding, masked)).value
    )


def expert_agent(world: RunConfig, expert_name: str, model: str | None = None) -> Agent:
    """The expert `expert_name` (not the oracle) built for a loop of `world`; a learned expert
    with the Q-network of `model` (by default its shipped file)."""
    setup = lookahead_setup(world) if expert_name == "lookahead" else None
    learned = model if expert_name in LEARNED_EXPERTS else None
    return make_agent(
        expert_name, world.highway.lanes_count, grid_config(world), model=learned, lookahead=setup
    )


def expert_episode(config: RunConfig, experts: DemonstrationConfig | str, seed: int) -> Demonstrations:
    """One episode of the decision MDP (its world and traffic drawn from `seed`) driven by the
    expert of its world (`experts`; a name: that expert on every world), with the learner's
    observations and rewards; with an action mask, an expert's command the loop would not carry
    out is recorded as the STAY it becomes. In a worker process it is deaf to Ctrl-C, as the
    training env workers are: the learner stops the run (with a checkpoint) itself."""
    if multiprocessing.parent_process() is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    env = HierarchicalHighwayEnv(config)
    observation, _ = env.reset(seed=seed)
    teachers = DemonstrationConfig(expert=experts) if isinstance(experts, str) else experts
    world = env.loop.config
    expert = expert_policy(world, teachers.expert_of(world.scenario), teachers.expert_model)
    observations, actions, rewards = [observation], [], []
    terminated = truncated = False
    while not (terminated or truncated):
        action = expert(env.loop)
        if env.action_mask and observation[action - N_ACTIONS] < 0.5:
            action = Command.STAY.value
        observation, reward, terminated, truncated, _ = env.step(action)
        observations.append(observation)
        actions.append(action)
        rewards.append(reward)
    env.close()
    train = config.train
    return Demonstrations.from_episode(
        np.stack(observations), np.array(actions), np.array(rewards), terminated, train.gamma, train.n_steps
    )


Expert = tuple[Agent, GridConfig, bool]
"""An expert as a batch of worlds asks it: the agent, the grid it decides on as the batch encodes it,
whether it sees the permitted commands after it."""


def batch_experts(config: RunConfig, experts: DemonstrationConfig) -> list[Expert] | None:
    """The expert of each world of `config`'s mix (`training_worlds` order) as a batch asks it, or
    None when one of them decides one world at a time: the oracle (it plans on copies of the loop),
    an encoding other than `observation` or `paper`, a grid feature the batch does not compute, or
    observations of several sizes on the roads an episode may draw."""
    found: list[Expert] = []
    for world in training_worlds(config).values():
        name = experts.expert_of(world.scenario)
        if name == "oracle":
            return None
        agent = expert_agent(world, name, experts.expert_model)
        if agent.encoding not in ("observation", "paper"):
            return None
        grid = decision_grid(world, agent)
        if any(feature not in BATCHED_FEATURES for feature in grid.features):
            return None
        if len(config.highway.lane_counts) > 1 and (grid.lanes != "ego" or grid.lane_code != "sides"):
            return None
        found.append((agent, grid, sees_permitted(agent)))
    return found


def batched_expert_episodes(
    config: RunConfig, experts: DemonstrationConfig, seeds: Sequence[int]
) -> list[Demonstrations] | None:
    """`expert_episode(config, experts, seed)` for every seed, their worlds stepped together as one
    `DecisionBatch` (each world drawn from its seed as the per-world env draws it, each expert
    deciding for its worlds on what the batch perceives): the same episodes, transition for
    transition; None when the batch or an expert does not run them so (`batch_experts`). Deaf to
    Ctrl-C in a worker process, as `expert_episode`."""
    if multiprocessing.parent_process() is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    teachers = batch_experts(config, experts)
    if teachers is None:
        return None
    try:
        batch = DecisionBatch(config, len(seeds))
    except BatchRefused:
        return None
    try:
        drawn = [batch.draw(seeding.np_random(seed)[0]) for seed in seeds]
        members = np.array([member for member, _ in drawn])
        observation = batch.reset([seed for _, seed in drawn], members.tolist())
        worlds = len(seeds)
        observations = [[observation[k]] for k in range(worlds)]
        actions: list[list[int]] = [[] for _ in range(worlds)]
        rewards: list[list[float]] = [[] for _ in range(worlds)]
        live, terminated = np.ones(worlds, dtype=bool), np.zeros(worlds, dtype=bool)
        while live.any():
            commands = np.full(worlds, Command.STAY.value, dtype=np.int64)
            for member, (agent, grid, with_permitted) in enumerate(teachers):
                deciding = live & (members == member)
                if deciding.any():
                    assert batch.loop.perceived is not None
                    seen = observe_batch(grid, batch.loop.perceived)
                    if with_permitted:
                        seen = np.concatenate([seen, batch.permitted()], axis=1)
                    decide_worlds([agent] * worlds, seen, deciding, commands)
            if batch.action_mask:
                refused = observation[np.arange(worlds), commands - N_ACTIONS] < 0.5
                commands[refused] = Command.STAY.value
            decided = batch.step(commands, live)
            observation = decided.observations
            for k in np.flatnonzero(live).tolist():
                observations[k].append(observation[k])
                actions[k].append(int(commands[k]))
                rewards[k].append(float(decided.rewards[k]))
            terminated |= decided.terminated
            live &= ~(decided.terminated | decided.truncated)
    finally:
        batch.close()
    train = config.train
    return [
        Demonstrations.from_episode(
            np.stack(observations[k]),
            np.array(actions[k]),
            np.array(rewards[k]),
            bool(terminated[k]),
            train.gamma,
            train.n_steps,
        )  # fmt: skip
        for k in range(worlds)
    ]


def collect_demonstrations(
    config: RunConfig, progress: bool = True, stop_requested: Callable[[], bool] = lambda: False
) -> Demonstrations:
    """`train.demonstrations.episodes` expert episodes over `train.envs` processes, in seed order
    (the result does not depend on the number of processes or on batching), in the worlds of
    `train.demonstrations.scenarios` (by default the training mix): as batches of worlds
    (`batched_expert_episodes`) when they run so, else one world at a time. `StopTraining` after
    the episode (or batch) under way once `stop_requested()` (nothing is kept: a resumed run records
    them again)."""
    demonstrations = config.train.demonstrations
    assert demonstrations is not None, "the run names no demonstrations"
    checked_expert_model(config)
    seeds = [child_seed(demonstrations.seed, k) for k in range(demonstrations.episodes)]
    worlds = demonstration_worlds(config)
    episodes: dict[int, Demonstrations] = {}
    with tqdm(total=len(seeds), unit="episode", desc="demonstrations", disable=not progress) as bar:
        if batch_experts(worlds, demonstrations) is not None:
            split = batches(seeds, config.train.envs)
            batched = partial(batched_expert_episodes, worlds, demonstrations)
            for index, recorded in completed(batched, split, config.train.envs):
                if recorded is None:
                    break
                start = sum(len(part) for part in split[:index])
                episodes |= {start + k: episode for k, episode in enumerate(recorded)}
                bar.update(len(recorded))
                if stop_requested():
                    raise StopTraining
        task = partial(expert_episode, worlds, demonstrations)
        missing = [k for k in range(len(seeds)) if k not in episodes]
        for index, episode in completed(task, [seeds[k] for k in missing], config.train.envs):
            episodes[missing[index]] = episode
            bar.update(1)
            if stop_requested():
                raise StopTraining
    return Demonstrations.concatenate([episodes[index] for index in range(len(seeds))])


_shared: dict[str, Demonstrations] | None = None
"""Within `recorded_once`: the last demonstrations recorded, by the config they were recorded for
with its seed left out."""


@contextmanager
def recorded_once() -> Iterator[None]:
    """Within the block, runs whose configs differ only in their seed (an ensemble's members)
    record their demonstrations once: the episodes are seeded from `train.demonstrations.seed`,
    not from the run's seed, and recorded in other processes or from generators of their own, so
    every member learns from the same arrays it would have recorded itself."""
    global _shared
    _shared = {}
    try:
        yield
    finally:
        _shared = None


def shared_now() -> dict[str, Demonstrations] | None:
    """What `recorded_once` holds now, for a process of its own to `adopt_shared`."""
    return None if _shared is None else dict(_shared)


def adopt_shared(shared: dict[str, Demonstrations] | None) -> None:
    """In a process of its own: record once as the process that handed it `shared`
    (`shared_now`) does."""
    global _shared
    _shared = None if shared is None else dict(shared)


def shared_demonstrations(
    config: RunConfig, progress: bool = True, stop_requested: Callable[[], bool] = lambda: False
) -> Demonstrations:
    """`collect_demonstrations(config)`, or within `recorded_once` the same arrays recorded
    already for a config that differs from `config` in its seed alone."""
    if _shared is None:
        return collect_demonstrations(config, progress, stop_requested)
    key = config.model_copy(update={"seed": 0}).model_dump_json()
    if key not in _shared:
        _shared.clear()
        _shared[key] = collect_demonstrations(config, progress, stop_requested)
    return _shared[key]


def start_from_demonstrations(
    model: DoubleDQN,
    config: RunConfig,
    validation: RealTimeValidation,
    progress: bool = True,
    stop_requested: Callable[[], bool] = lambda: False,
) -> None:
    """Before the first episode: record the expert, pre-train on its episodes, and validate the
    pre-trained model as the first candidate to keep (at step 0). A stop (`stop_requested()`)
    ends recording or pre-training at the next episode or gradient step with `StopTraining`."""
    settings = config.train.demonstrations
    assert settings is not None, "the run names no demonstrations"
    model.demonstrations = shared_demonstrations(config, progress, stop_requested)

    def stepped(bar: tqdm) -> None:
        bar.update(1)
        if stop_requested():
            raise StopTraining

    steps = settings.pretrain_steps
    with tqdm(total=steps, unit="step", desc="pre-training", disable=not progress) as bar:
        model.pretrain(steps, config.train.batch_size, partial(stepped, bar))
    validation.validate_start(model)


def demonstrations_used(config: RunConfig, model: object) -> DemonstrationsUsed | None:
    """The demonstrations a run learnt from, for its summary (None when it learnt from none)."""
    settings, demonstrations = config.train.demonstrations, getattr(model, "demonstrations", None)
    if settings is None or demonstrations is None:
        return None
    return DemonstrationsUsed(
        expert=settings.expert,
        experts=dict(settings.experts),
        expert_model=settings.expert_model,
        episodes=settings.episodes,
        transitions=len(demonstrations),
        scenarios=tuple(settings.scenarios),
    )
