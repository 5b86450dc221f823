"""Double DQN (van Hasselt et al., 2016) on stable-baselines3: `DQN` with `train()` overridden.

The only change is the TD target: the online network picks the next action, the target network
evaluates it, y = r + gamma * (1 - done) * Q_target(s', argmax_a Q_online(s', a)).
"""

from __future__ import annotations

import numpy as np
import torch as th
from stable_baselines3 import DQN
from torch.nn import functional as F


def double_q_target(
    rewards: th.Tensor,
    dones: th.Tensor,
    discounts: th.Tensor | float,
    next_q_online: th.Tensor,
    next_q_target: th.Tensor,
) -> th.Tensor:
    """Double-Q TD target, shape (batch, 1)."""
    next_actions = next_q_online.argmax(dim=1, keepdim=True)
    next_values = th.gather(next_q_target, dim=1, index=next_actions)
    return rewards + (1 - dones) * discounts * next_values


class DoubleDQN(DQN):
    """SB3's DQN with the Double-DQN target."""

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses = []
        for _ in range(gradient_steps):
            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma
            with th.no_grad():
                target_q_values = double_q_target(
                    replay_data.rewards,
                    replay_data.dones,
                    discounts,
                    self.q_net(replay_data.next_observations),
                    self.q_net_target(replay_data.next_observations),
                )
            current_q_values = th.gather(
                self.q_net(replay_data.observations), dim=1, index=replay_data.actions.long()
            )
            loss = F.smooth_l1_loss(current_q_values, target_q_values)
            losses.append(loss.item())
            self.policy.optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", np.mean(losses))
