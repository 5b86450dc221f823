"""The trainer behind `drivestack train` and `sweep`: the decision layer trained inside the full
closed loop.

DDQN / DQN run on stable-baselines3 with the paper's real-time validation (the best model is kept),
TensorBoard logs and periodic checkpoints; tabular Q-learning runs on the tabular state. Every
file written is a safe model file (`planner.model_file`): weights, optimizer moments, the replay
buffer and counters, so `--resume DIR` continues where the last checkpoint left off.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, ProgressBarCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv
from tqdm import tqdm

from planner.learned import export_q_network, save_q_table
from planner.model_file import CHECKPOINT, ModelFileError, header_check, load_checkpoint, save_model
from planner.model_metadata import ModelMetadata
from planner.scores import Validation
from planner.tabular import QLearning
from planner.validation import RealTimeValidation
from records import child_seed
from stack.settings.run import RunConfig, grid_config, load_config, write_config
from stack.training.batch_validation import BatchedValidation
from stack.training.checkpoint import Checkpoint, DqnCounters, TabularCounters, read_checkpoint
from stack.training.checks import checkpoint_bytes, demonstration_rows
from stack.training.decision_env import HierarchicalHighwayEnv
from stack.training.demonstrations import demonstrations_used, start_from_demonstrations
from stack.training.envs import (
    EnvWorkerDied,
    StopTraining,
    close_env,
    stop_signals,
    training_env,
    worker_death,
)
from stack.training.model import Checkpoints, build_dqn, initial_model, model_metadata, warm_start
from stack.training.report import write_training_summary
from stack.training.state import (
    Layout,
    dqn_layout,
    dqn_state,
    restore_dqn_state,
    restore_tabular_state,
    tabular_layout,
    tabular_state,
)
from stack.training.summary import TrainSummary

BEST = "best.npz"
FINAL = "final.npz"

SaveModel = Callable[[Any, Path, ModelMetadata], Path]
"""`export_q_network` or `save_q_table`: (model, path, metadata) -> the file written."""


class Trainer:
    """One training run in `out`: fresh, or resumed from `out/checkpoint.npz`."""

    model: DQN | QLearning

    def __init__(
        self,
        config: RunConfig,
        out: Path,
        progress: bool = True,
        on_validation: Callable[[Validation], None] | None = None,
        ray: str | None = None,
    ) -> None:
        """`on_validation` hears every validation (a sweep reports them to Ray Tune); with `ray`
        (an address: `local`, `auto`, HOST:PORT) the batched worlds' shards are Ray actors there."""
        self.config, self.out, self.progress = config, Path(out), progress
        self.on_validation = on_validation
        self.start = initial_model(config)
        self.env: Monitor | VecEnv = training_env(config, ray)
        self.validation_env = HierarchicalHighwayEnv(config)
        self.batched_validation = (
            BatchedValidation.of(config)
            if config.train.worlds is not None and config.train.algorithm != "tabular"
            else None
        )
        self.history: list[Validation] = []
        self.best: dict[str, tuple[float, float] | None] | None = None
        self.started = time.perf_counter()
        self.elapsed_before = 0.0

    @classmethod
    def resume(cls, out: Path, steps: int | None, progress: bool = True, ray: str | None = None) -> Trainer:
        config = load_config(Path(out) / "config.yaml", train__steps=steps)
        return cls(config, out, progress, ray=ray)

    def metadata(self, steps: int) -> ModelMetadata:
        return model_metadata(self.config, self.validation_env, steps)

    def run(self) -> TrainSummary:
        """Train to `train.steps`, or until SIGINT / SIGTERM (a checkpoint first), and write the
        summary; further signals only wait for the files. A dead env worker: `EnvWorkerDied`."""
        self.out.mkdir(parents=True, exist_ok=True)
        write_config(self.config, self.out / "config.yaml", "the resolved config; --resume reads it")
        self.stop_requested = interrupted = False
        with stop_signals(self._request_stop):
            try:
                steps = (
                    self._train_tabular() if self.config.train.algorithm == "tabular" else self._train_dqn()
                )
            except StopTraining:
                interrupted, steps = True, self._steps_done()
            except KeyboardInterrupt:
                self.stop_requested = interrupted = True
                steps = self._save_checkpoint()
            except (EOFError, ConnectionError) as error:
                death = worker_death(self.env, self.out, error)
                close_env(self.env, a_worker_died=True)
                raise EnvWorkerDied(death) from None
            finally:
                close_env(self.env)
                if self.batched_validation is not None:
                    self.batched_validation.close()
            return self._finish(steps, interrupted)

    def _request_stop(self, signum: int, frame: object) -> None:
        """SIGINT / SIGTERM: stop at the next consistent point, with a checkpoint; a second
        signal only says so again (it never cuts the checkpoint short)."""
        self.stop_requested = True

    def _steps_done(self) -> int:
        return int(self.model.steps if isinstance(self.model, QLearning) else self.model.num_timesteps)

    def _improved(self, save: SaveModel) -> Callable[[Any, Validation], None]:
        def on_improvement(model: Any, validation: Validation) -> None:
            save(model, self.out / BEST, replace(self.metadata(validation.step), validation=validation))

        return on_improvement

    def _validation_callback(self, save: SaveModel) -> RealTimeValidation:
        v = self.config.train.validation
        return RealTimeValidation(
            self.validation_env,
            v.short_every,
            v.short_episodes,
            v.long_every,
            v.long_episodes,
            v.seed,
            self._improved(save),
            self.history,
            self.best,
            self._heard,
            self.batched_validation.measure if self.batched_validation is not None else None,
        )

    def _heard(self, validation: Validation) -> None:
        """Show every validation (per world for a training mix) above the progress bar, then pass
        it on to `on_validation`."""
        if self.progress:
            tqdm.write(validation.line())
        if self.on_validation is not None:
            self.on_validation(validation)

    # --- DDQN / DQN -------------------------------------------------------------------------
    def _train_dqn(self) -> int:
        self.model = build_dqn(self.config, self.env, self.out / "tensorboard")
        resumed = (self.out / CHECKPOINT).is_file()
        callbacks: list[BaseCallback] = []
        if resumed:
            arrays, metadata = self._checkpoint(dqn_layout(self.model, demonstration_rows(self.config)))
            try:
                checkpoint = read_checkpoint(metadata, DqnCounters)
                callbacks.append(restore_dqn_state(self.model, arrays, checkpoint.counters))
            except (KeyError, RuntimeError, ValueError, TypeError) as error:
                message = str(error).splitlines()[0][:120] if str(error) else type(error).__name__
                raise ModelFileError(
                    f"{self.out / CHECKPOINT}: does not fit this run's model ({message})"
                ) from None
            self._restore_common(checkpoint)
        elif self.start is not None:
            warm_start(self.model, self.start, grid_config(self.config), self.config.highway.lanes_count)
        self.validation = self._validation_callback(export_q_network)
        if not resumed and self.config.train.demonstrations is not None:
            start_from_demonstrations(
                self.model,  # type: ignore[arg-type]
                self.config,
                self.validation,
                self.progress,
                lambda: self.stop_requested,
            )
        elif not resumed and self.start is not None:
            self.validation.validate_start(self.model)
        checkpoints = Checkpoints(
            self.config.train.checkpoint_every, self._save_checkpoint, lambda: self.stop_requested
        )
        callbacks += [self.validation, checkpoints]
        if self.progress:
            callbacks.append(ProgressBarCallback())
        if (remaining := self.config.train.steps - self.model.num_timesteps) <= 0:
            return int(self.model.num_timesteps)
        self.model.learn(
            remaining,
            callback=CallbackList(callbacks),
            reset_num_timesteps=not resumed,
            tb_log_name=self.config.train.algorithm,
        )
        return self._save_checkpoint()

    # --- tabular Q-learning -----------------------------------------------------------------
    def _train_tabular(self) -> int:
        train = self.config.train
        self.model = QLearning.for_space(
            self.validation_env.observation_space,
            alpha=train.tabular_alpha,
            gamma=train.gamma,
            epsilon=train.tabular_epsilon,
            seed=self.config.seed,
        )
        assert isinstance(self.env, Monitor), "tabular training steps one env"
        observation = None
        if (self.out / CHECKPOINT).is_file():
            arrays, metadata = self._checkpoint(tabular_layout(self.model))
            try:
                tabular = read_checkpoint(metadata, TabularCounters)
                observation = restore_tabular_state(self.model, self.env, arrays, tabular.counters)
            except (KeyError, ValueError, TypeError) as error:
                raise ModelFileError(f"{self.out / CHECKPOINT}: does not fit this run ({error})") from None
            self._restore_common(tabular)
        validation = self._validation_callback(save_q_table)
        validation.model = self.model

        def on_step(agent: QLearning, info: dict) -> bool:
            validation.at_step(agent.steps)
            if agent.steps % train.checkpoint_every == 0 or self.stop_requested:
                self._save_checkpoint()
            if self.stop_requested:
                raise StopTraining
            return True

        self.validation = validation
        if (remaining := train.steps - self.model.steps) <= 0:
            return self.model.steps
        self.model.learn(self.env, remaining, child_seed(self.config.seed, 0), on_step, observation)
        return self._save_checkpoint()

    # --- shared -------------------------------------------------------------------------------
    def _checkpoint(self, layout: Layout) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The run's checkpoint file (arrays, metadata), refused in one line (ModelFileError)
        unless it is one: every array as `layout` (what this run's model holds) says, checked from
        the `.npy` headers before any array is read."""
        path, bound = self.out / CHECKPOINT, checkpoint_bytes(self.config)
        return load_checkpoint(path, max_bytes=bound, expected=header_check(layout))

    def _restore_common(self, checkpoint: Checkpoint[DqnCounters] | Checkpoint[TabularCounters]) -> None:
        self.history, self.best = RealTimeValidation.restore(checkpoint.validation)
        self.elapsed_before = checkpoint.elapsed_s

    def _elapsed(self) -> float:
        return self.elapsed_before + time.perf_counter() - self.started

    def _save_checkpoint(self) -> int:
        """Write everything needed to resume; returns the steps done."""
        if not hasattr(self, "model"):
            return 0
        validation = getattr(self, "validation", None)
        state = validation.state() if validation else {"best": None, "history": []}
        checkpoint: Checkpoint[DqnCounters] | Checkpoint[TabularCounters]
        if isinstance(self.model, QLearning):
            assert isinstance(self.env, Monitor), "tabular training steps one env"
            arrays, tabular = tabular_state(self.model, self.env)
            checkpoint = Checkpoint(tabular, state, self._elapsed())
        else:
            arrays, dqn = dqn_state(self.model)
            checkpoint = Checkpoint(dqn, state, self._elapsed())
        save_model(self.out / CHECKPOINT, arrays, checkpoint.to_json())
        return checkpoint.counters.num_timesteps

    def _finish(self, steps: int, interrupted: bool) -> TrainSummary:
        if steps and not interrupted:
            if isinstance(self.model, QLearning):
                save_q_table(self.model, self.out / FINAL, self.metadata(steps))
            else:
                export_q_network(self.model, self.out / FINAL, self.metadata(steps))
        history = self.validation.history if hasattr(self, "validation") else self.history
        return write_training_summary(
            self.config,
            self.out,
            history,
            self.out / BEST,
            steps=steps,
            wall_time_s=round(self._elapsed(), 1),
            interrupted=interrupted,
            demonstrations=demonstrations_used(self.config, getattr(self, "model", None)),
        )
