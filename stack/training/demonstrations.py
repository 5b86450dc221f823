"""An expert's demonstrations for DQfD-style training (`train.demonstrations`): recorded in the
decision MDP the learner trains in (in the worlds of `train.demonstrations.scenarios` when it names
some), on training seeds of their own stream, spread over processes."""

from __future__ import annotations

import multiprocessing
import signal
from collections.abc import Callable
from functools import partial

import numpy as np
from tqdm import tqdm

from perception.grid import OccupancyGridBuilder
from planner.agents import decide, sees_permitted
from planner.ddqn import Demonstrations, DoubleDQN
from planner.factory import make_agent
from planner.validation import RealTimeValidation
from records import N_ACTIONS, Command, child_seed
from stack.agents.oracle import Oracle
from stack.loop.closed_loop import ClosedLoop
from stack.runs.kept import lookahead_setup
from stack.runs.model_fit import checked_expert_model
from stack.runtime.executors import completed
from stack.settings.run import RunConfig, demonstration_worlds, grid_config
from stack.settings.train import LEARNED_EXPERTS, DemonstrationConfig
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
    setup = lookahead_setup(world) if expert_name == "lookahead" else None
    learned = model if expert_name in LEARNED_EXPERTS else None
    expert = make_agent(expert_name, lanes, grid, model=learned, lookahead=setup)
    view, masked = OccupancyGridBuilder(expert.grid_config or grid), sees_permitted(expert)
    return lambda loop: (
        decide(expert, loop.observation(view.build(loop.perceived), expert.encoding, masked)).value
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


def collect_demonstrations(
    config: RunConfig, progress: bool = True, stop_requested: Callable[[], bool] = lambda: False
) -> Demonstrations:
    """`train.demonstrations.episodes` expert episodes over `train.envs` processes, in seed order
    (the result does not depend on the number of processes), in the worlds of
    `train.demonstrations.scenarios` (by default the training mix). `StopTraining` after the
    episode under way once `stop_requested()` (nothing is kept: a resumed run records them again)."""
    demonstrations = config.train.demonstrations
    assert demonstrations is not None, "the run names no demonstrations"
    checked_expert_model(config)
    seeds = [child_seed(demonstrations.seed, k) for k in range(demonstrations.episodes)]
    episodes: dict[int, Demonstrations] = {}
    task = partial(expert_episode, demonstration_worlds(config), demonstrations)
    with tqdm(total=len(seeds), unit="episode", desc="demonstrations", disable=not progress) as bar:
        for index, episode in completed(task, seeds, config.train.envs):
            episodes[index] = episode
            bar.update(1)
            if stop_requested():
                raise StopTraining
    return Demonstrations.concatenate([episodes[index] for index in range(len(seeds))])


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
    model.demonstrations = collect_demonstrations(config, progress, stop_requested)

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
