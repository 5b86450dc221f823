"""Running seeded episodes: one at a time or spread over processes, results in episode order."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import closing
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from tqdm import tqdm

from planner.factory import model_label, model_path
from stack.results.episode_result import EpisodeResult, summarize
from stack.runs.alone import run_episode
from stack.runs.batch_episodes import RAY_BATCH_WORLDS, batch_refusal, batches, run_batched
from stack.runtime.executors import completed
from stack.settings.run import RunConfig, drivers_of
from stack.worlds.drivers import HIGHWAY_ENV


@dataclass
class RunResults:
    summary: dict
    episodes: list[EpisodeResult]
    frames: list[np.ndarray]


def run(
    config: RunConfig,
    video: bool = False,
    progress: bool = True,
    jobs: int = 1,
    ray: str | None = None,
    on_finished: Callable[[EpisodeResult], None] | None = None,
    done: Sequence[EpisodeResult] = (),
    record: Path | None = None,
    snapshot: bool = True,
) -> RunResults:
    """Run `config.episodes` seeded episodes over `jobs` processes, or as Ray tasks with `ray` (an
    address, see `stack.runtime.executors`), as batches of worlds where the config allows
    (`stack.runs.batch_episodes`); results are ordered by episode, identical for any `jobs`, `ray`
    or batching. Here a batch hands on each episode as it ends; over processes or Ray a batch comes
    whole, and a stop loses the batches under way. With `video`, episode 0 (unless done) runs here
    and keeps its frames; with `snapshot` (the default), it runs alone and keeps its road's
    snapshot (a batch keeps none). `done` are episodes an earlier run of `config` finished: they
    count as they are and are not run again. Ctrl-C keeps the finished episodes
    (`summary["interrupted"]`); `on_finished` sees each as it finishes (if it raises, the episodes
    still running are stopped before the error goes on).
    `record`: a folder each episode run writes its recording into (`run_episode`)."""
    frames: list[np.ndarray] = []
    results: dict[int, EpisodeResult] = {episode.episode: episode for episode in done}
    pending = [episode for episode in range(config.episodes) if episode not in results]
    interrupted = False
    bar = tqdm(total=config.episodes, initial=len(results), unit="episode", disable=not progress)

    def finished(result: EpisodeResult) -> None:
        results[result.episode] = result
        bar.update(1)
        bar.set_postfix(crashes=sum(r.crashed for r in results.values()))
        if on_finished is not None:
            on_finished(result)

    stepped_alone = stepping_reason(config, record)
    try:
        if (video or snapshot) and pending and pending[0] == 0:
            finished(run_episode(config, pending.pop(0), frames if video else None, record))
        if stepped_alone is None:
            split = batches(pending, jobs) if ray is None else batches(pending, 1, RAY_BATCH_WORLDS)
            if ray is None and (jobs <= 1 or len(split) <= 1):
                for batch in split:
                    run_batched(config, batch, on_finished=finished)
            else:
                batched = partial(run_batched, config)
                with closing(completed(batched, split, jobs, ray)) as batches_coming:
                    for _, results_of_batch in batches_coming:
                        for result in results_of_batch:
                            finished(result)
        else:
            task = partial(run_episode, config, record=record)
            with closing(completed(task, pending, jobs, ray)) as results_coming:
                for _, result in results_coming:
                    finished(result)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    if not results:
        raise KeyboardInterrupt
    ordered = [results[episode] for episode in sorted(results)]
    summary = summarize(
        ordered,
        scenario=config.scenario,
        **drivers_entry(config),
        agent=config.planner.agent,
        model=model_label(model_path(config.planner.agent, config.planner.model)),
        controller=config.controller.type,
        backend=config.sim.backend,
        plant=config.sim.plant,
        seed=config.seed,
        stepping="per-world" if stepped_alone else "batched",
        **({"stepping_reason": stepped_alone} if stepped_alone else {}),
        interrupted=interrupted,
    )
    return RunResults(summary=summary, episodes=ordered, frames=frames)


def drivers_entry(config: RunConfig) -> dict[str, object]:
    """The summary's `drivers` (the traffic's driver population, `stack.sim.drivers`), left out for
    highway-env's own drivers (summaries of runs before populations stay as they were)."""
    drivers = drivers_of(config.highway)
    return {} if drivers == HIGHWAY_ENV else {"drivers": drivers}


def stepping_reason(config: RunConfig, record: Path | None) -> str | None:
    """Why `config`'s episodes run one world at a time (one line), or None: they run as batches of
    worlds (`batch_refusal`; a recorded run steps each world alone to record it). A batched run
    still runs its episode 0 alone when it keeps that episode's video or road snapshot."""
    if record is not None:
        return "recorded episodes (--record) run one world at a time"
    return batch_refusal(config)
