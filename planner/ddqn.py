"""Double DQN (van Hasselt et al., 2016) on stable-baselines3: `DQN` with `train()` overridden,
optionally learning from an expert's demonstrations as DQfD does (Hester et al., 2018).

The TD target: the online network picks the next action, the target network evaluates it,
y = r + gamma * (1 - done) * Q_target(s', argmax_a Q_online(s', a)). With demonstrations, a share
of every batch is drawn from them and those rows add DQfD's large-margin loss,
max_a [Q(s, a) + margin * (a != a_E)] - Q(s, a_E), which keeps the expert's action ahead of the
others by `margin`; `pretrain` takes gradient steps on demonstrations alone before any episode.
With `overlap`, the gradient steps due after a step of the environments run while the environments'
processes take the next step (`LearningWhileStepping`), so the learner and the simulation share
the cores instead of taking turns.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any, ClassVar, NamedTuple

import numpy as np
import torch as th
from stable_baselines3 import DQN
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.utils import polyak_update
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn
from stable_baselines3.dqn.policies import DQNPolicy, QNetwork
from torch.nn import functional as F

from planner.mobil import MobilPrior
from records import N_ACTIONS


def permitted_columns(observations: th.Tensor) -> th.Tensor:
    """The safety layer's permitted commands that end an observation of an agent trained with
    `action_mask` (`N_ACTIONS` values, 1 permitted, 0 refused), shape (batch, N_ACTIONS)."""
    return observations[:, -N_ACTIONS:]


def masked(q_values: th.Tensor, permitted: th.Tensor | None) -> th.Tensor:
    """`q_values` with the commands not `permitted` (mask value below 0.5) at -inf, so that no
    argmax picks them; unchanged without a mask."""
    return q_values if permitted is None else q_values.masked_fill(permitted < 0.5, -th.inf)


def double_q_target(
    rewards: th.Tensor,
    dones: th.Tensor,
    discounts: th.Tensor | float,
    next_q_online: th.Tensor,
    next_q_target: th.Tensor,
    next_permitted: th.Tensor | None = None,
) -> th.Tensor:
    """Double-Q TD target, shape (batch, 1); with `next_permitted`, the online network picks the
    next action among the commands the safety layer permits there (invalid-action masking)."""
    next_actions = masked(next_q_online, next_permitted).argmax(dim=1, keepdim=True)
    next_values = th.gather(next_q_target, dim=1, index=next_actions)
    return rewards + (1 - dones) * discounts * next_values


def margin_loss(q_values: th.Tensor, expert_actions: th.Tensor, margin: float) -> th.Tensor:
    """DQfD's supervised loss, mean over the batch: how far the best action, with every action but
    the expert's (shape (batch, 1)) raised by `margin`, lies above the expert's action's value."""
    raised = q_values + margin * (1 - F.one_hot(expert_actions.reshape(-1), q_values.shape[1]).float())
    return (raised.max(dim=1).values - th.gather(q_values, 1, expert_actions).reshape(-1)).mean()


class Batch(NamedTuple):
    """Transitions as the loss takes them: every tensor has one row per transition; `rewards` are
    n-step returns and `discounts` gamma^k for the k steps they sum."""

    observations: th.Tensor
    actions: th.Tensor
    next_observations: th.Tensor
    dones: th.Tensor
    rewards: th.Tensor
    discounts: th.Tensor


@dataclass
class Demonstrations:
    """An expert's transitions with n-step returns (fewer steps where its episode ended): row i is
    an observation, the expert's action there, the discounted reward of the next k <= n steps, the
    observation k steps later, whether the episode terminated within them and gamma^k."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_observations: np.ndarray
    dones: np.ndarray
    discounts: np.ndarray

    @classmethod
    def from_episode(
        cls,
        observations: np.ndarray,
        actions: np.ndarray,
        rewards: np.ndarray,
        terminated: bool,
        gamma: float,
        n_steps: int,
    ) -> Demonstrations:
        """One episode of T decisions: T + 1 observations, T actions and rewards; `terminated`
        when it ended in a crash (a time limit bootstraps from the last observation)."""
        steps = len(actions)
        ends = np.minimum(np.arange(steps) + n_steps, steps)
        returns = np.array(
            [sum(gamma**k * rewards[t + k] for k in range(end - t)) for t, end in enumerate(ends)]
        )
        return cls(
            observations[:steps].astype(np.float32),
            np.asarray(actions, dtype=np.int64),
            returns.astype(np.float32),
            observations[ends].astype(np.float32),
            ((ends == steps) & terminated).astype(np.float32),
            (gamma ** (ends - np.arange(steps))).astype(np.float32),
        )

    @classmethod
    def concatenate(cls, parts: list[Demonstrations]) -> Demonstrations:
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))

    def __len__(self) -> int:
        return len(self.actions)

    def arrays(self) -> dict[str, np.ndarray]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_arrays(
        cls, arrays: dict[str, np.ndarray], observation_size: int, actions: int
    ) -> Demonstrations:
        """The demonstrations `arrays()` gave (a checkpoint's), checked: every field, one row per
        transition, observations of `observation_size` values, actions below `actions`, all finite;
        ValueError otherwise."""
        names = [f.name for f in fields(cls)]
        if sorted(arrays) != sorted(names):
            raise ValueError(f"demonstrations hold {sorted(arrays)}, expected {names}")
        rows = len(arrays["actions"])
        shapes = {name: (rows, observation_size) if "observations" in name else (rows,) for name in names}
        for name, shape in shapes.items():
            if arrays[name].shape != shape or not np.isfinite(arrays[name]).all():
                raise ValueError(f"demonstrations/{name}: expected {shape} finite values")
        chosen = arrays["actions"]
        if (
            rows == 0
            or not np.issubdtype(chosen.dtype, np.integer)
            or not ((chosen >= 0) & (chosen < actions)).all()
        ):
            raise ValueError(f"demonstrations/actions: expected at least one, integers in [0, {actions})")
        return cls(**{name: np.asarray(arrays[name]) for name in names})

    def sample(self, size: int) -> Batch:
        """`size` rows drawn with replacement from numpy's global generator (SB3's replay buffer
        draws from it too, and checkpoints keep its state)."""
        rows = np.random.randint(0, len(self), size=size)

        def column(values: np.ndarray) -> th.Tensor:
            return th.as_tensor(values[rows]).reshape(size, -1)

        return Batch(
            column(self.observations),
            column(self.actions),
            column(self.next_observations),
            column(self.dones),
            column(self.rewards),
            column(self.discounts),
        )


class PriorQNetwork(QNetwork):
    """SB3's Q-network whose greedy action adds `prior`'s bonus to MOBIL's proposed change (None:
    SB3's argmax) and, with `action_mask`, picks among the commands its observation permits."""

    prior: MobilPrior | None = None
    action_mask: bool = False

    def _predict(self, observation: th.Tensor, deterministic: bool = True) -> th.Tensor:  # type: ignore[override]
        q_values = self(observation)
        if self.prior is not None:
            q_values = q_values + th.as_tensor(self.prior.bonuses(observation.cpu().numpy()))
        if self.action_mask:
            q_values = masked(q_values, permitted_columns(observation))
        return q_values.argmax(dim=1).reshape(-1)


class PriorDQNPolicy(DQNPolicy):
    """SB3's MLP DQN policy on `PriorQNetwork`s."""

    def make_q_net(self) -> QNetwork:
        net_args = self._update_features_extractor(self.net_args, features_extractor=None)
        return PriorQNetwork(**net_args).to(self.device)


class DoubleDQN(DQN):
    """SB3's DQN with the Double-DQN target. Once `demonstrations` are set, `demonstration_share`
    of every batch is drawn from them, with DQfD's margin loss (`margin`, weight `margin_weight`).
    With a `mobil_prior` its greedy actions (in training's rollouts and in validation) are the
    prior's (`planner.mobil.MobilPrior`); the TD target stays the Q-network's own. With
    `action_mask`, every observation ends with the safety layer's permitted commands
    (`permitted_columns`): greedy actions, exploration and the TD target's next action are chosen
    among them, so the agent learns what it may do and is never taught by a refused command.
    With `overlap`, the gradient steps SB3 asks for after a step of the environments are put off
    until the next step's actions are on their way (`pending_gradient_steps` until then): they
    learn from the transitions up to the step before while the environments' processes step, one
    step staler than SB3's order and as deterministic (a different run from the one without)."""

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"MlpPolicy": PriorDQNPolicy}

    def __init__(
        self,
        *args: Any,
        demonstration_share: float = 0.25,
        margin: float = 0.8,
        margin_weight: float = 1.0,
        mobil_prior: MobilPrior | None = None,
        action_mask: bool = False,
        overlap: bool = False,
        **kwargs: Any,
    ) -> None:
        self.demonstrations: Demonstrations | None = None
        self.demonstration_share, self.margin, self.margin_weight = demonstration_share, margin, margin_weight
        self.action_mask, self.overlap = action_mask, overlap
        self.pending_gradient_steps = 0
        self._stepping: LearningWhileStepping | None = None
        super().__init__(*args, **kwargs)
        if isinstance(self.q_net, PriorQNetwork):
            self.q_net.prior, self.q_net.action_mask = mobil_prior, action_mask
        assert not (mobil_prior or action_mask) or isinstance(self.q_net, PriorQNetwork), (
            "a MOBIL prior and an action mask need MlpPolicy"
        )

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """SB3's epsilon-greedy `predict`; with `action_mask`, an exploring step draws among the
        permitted commands of each observation (from the action space's generator, which
        checkpoints keep)."""
        if not self.action_mask:
            return super().predict(observation, state, episode_start, deterministic)
        if deterministic or np.random.rand() >= self.exploration_rate:
            return self.policy.predict(observation, state, episode_start, deterministic=True)
        assert isinstance(observation, np.ndarray), "an action mask needs array observations"
        drawn = self._permitted_draws(observation)
        return (drawn if observation.ndim > 1 else drawn[0]), state

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """SB3's rollout action; with `action_mask`, the warm-up's uniform draws (before
        `learning_starts`) are among the permitted commands too."""
        if not self.action_mask or self.num_timesteps >= learning_starts:
            return super()._sample_action(learning_starts, action_noise, n_envs)
        assert isinstance(self._last_obs, np.ndarray), "an action mask needs array observations"
        drawn = self._permitted_draws(self._last_obs)
        return drawn, drawn

    def _permitted_draws(self, observation: np.ndarray) -> np.ndarray:
        """One command per row of `observation`, drawn uniformly among those its last
        `N_ACTIONS` values permit, from the action space's generator."""
        rows = observation.reshape(-1, observation.shape[-1])
        permitted = rows[:, -N_ACTIONS:] >= 0.5
        return np.array([self.action_space.sample(mask=row.astype(np.int8)) for row in permitted])

    def pretrain(
        self, gradient_steps: int, batch_size: int, on_step: Callable[[], object] | None = None
    ) -> float:
        """Gradient steps on demonstrations alone (DQfD's pre-training), the target network
        copied every `target_update_interval` of them; `on_step` hears each (progress); returns the
        last step's loss."""
        assert self.demonstrations is not None, "pretraining needs demonstrations"
        self.policy.set_training_mode(True)
        loss = float("nan")
        for step in range(1, gradient_steps + 1):
            loss = self._gradient_step(self.demonstrations.sample(batch_size), batch_size)
            if step % self.target_update_interval == 0:
                polyak_update(self.q_net.parameters(), self.q_net_target.parameters(), 1.0)
            if on_step is not None:
                on_step()
        polyak_update(self.q_net.parameters(), self.q_net_target.parameters(), 1.0)
        return loss

    def collect_rollouts(self, env: VecEnv, *args: Any, **kwargs: Any) -> Any:
        """SB3's rollout; with `overlap`, on `env` wrapped so that the pending gradient steps run
        once each step's actions are sent."""
        if self.overlap:
            if self._stepping is None or self._stepping.venv is not env:
                self._stepping = LearningWhileStepping(env, self.learn_pending)
            env = self._stepping
        return super().collect_rollouts(env, *args, **kwargs)

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        """`gradient_steps` steps on batches of `batch_size`; with `overlap`, put off to the next
        step of the environments (`learn_pending`)."""
        if self.overlap:
            self.pending_gradient_steps += gradient_steps
            return
        self._train(gradient_steps, batch_size)

    def learn_pending(self) -> None:
        """The gradient steps put off (`overlap`), on the replay buffer as it stands."""
        if self.pending_gradient_steps:
            steps, self.pending_gradient_steps = self.pending_gradient_steps, 0
            self._train(steps, self.batch_size)

    def _train(self, gradient_steps: int, batch_size: int) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        demonstrated = round(batch_size * self.demonstration_share) if self.demonstrations else 0
        losses = []
        for _ in range(gradient_steps):
            replay = self.replay_buffer.sample(batch_size - demonstrated, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay.discounts
            if discounts is None:
                discounts = th.full_like(replay.rewards, self.gamma)
            batch = Batch(
                replay.observations,
                replay.actions.long(),
                replay.next_observations,
                replay.dones,
                replay.rewards,
                discounts,
            )
            if demonstrated:
                expert = self.demonstrations.sample(demonstrated)  # type: ignore[union-attr]
                batch = Batch(*(th.cat([ours, theirs]) for ours, theirs in zip(batch, expert, strict=True)))
            losses.append(self._gradient_step(batch, demonstrated))
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))

    def _gradient_step(self, batch: Batch, demonstrated: int) -> float:
        """One Adam step on the TD loss of `batch`, plus the margin loss on its last
        `demonstrated` rows (the expert's)."""
        with th.no_grad():
            target_q_values = double_q_target(
                batch.rewards,
                batch.dones,
                batch.discounts,
                self.q_net(batch.next_observations),
                self.q_net_target(batch.next_observations),
                permitted_columns(batch.next_observations) if self.action_mask else None,
            )
        q_values = self.q_net(batch.observations)
        loss = F.smooth_l1_loss(th.gather(q_values, dim=1, index=batch.actions), target_q_values)
        if demonstrated:
            loss = loss + self.margin_weight * margin_loss(
                q_values[-demonstrated:], batch.actions[-demonstrated:], self.margin
            )
        self.policy.optimizer.zero_grad()
        loss.backward()
        th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
        self.policy.optimizer.step()
        return float(loss.item())


class LearningWhileStepping(VecEnvWrapper):
    """`venv` whose `step_async` sends the actions, then calls `learn` before the step is awaited:
    with the environments in other processes, `learn` runs while they step."""

    def __init__(self, venv: VecEnv, learn: Callable[[], None]) -> None:
        super().__init__(venv)
        self.learn = learn

    def reset(self) -> Any:
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        self.venv.step_async(actions)
        self.learn()

    def step_wait(self) -> VecEnvStepReturn:
        return self.venv.step_wait()
