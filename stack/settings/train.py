"""`train:` settings: algorithm, budget, parallel environments, scenario mix, SB3 hyper-parameters,
reward and the real-time validation."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator

from planner.mobil import MAX_PRIOR
from planner.networks import MAX_MEMBERS, NET_ARCHS
from records import ENCODINGS, LEARNED_AGENTS, SEED_LIMIT, Encoding, LearnedAgentName, one_of, unknown_name
from stack.worlds import scenarios

LEARNED_EXPERTS = ("ddqn", "dqn")
"""The learned agents that can teach (`train.demonstrations.expert_model` names their file)."""
MAX_STEPS = 1_000_000_000
"""Upper bound of every step count and period [environment steps] (the largest `train.steps`)."""
MAX_SPEED_RANGE = 100.0
"""Upper end of the reward's speed range [m/s]."""
MAX_SHARE = 1e6
"""Largest share of a scenario in a mix (`train.scenarios`, `train.demonstrations.scenarios`; shares
are relative: they are divided by their sum, which must stay finite)."""
MAX_WORLDS = 1_024
"""Most worlds one batched training env steps together (`train.worlds`)."""
MAX_REPLAY_RATIO = 64.0
"""Most gradient steps per decision collected (`train.replay_ratio`)."""
MAX_REWARD = 1_000.0
"""Upper bound of every reward term and loss weight, by magnitude: well past any useful value,
far from where float32 arithmetic overflows."""


class Strict(BaseModel):
    """A config section: unknown keys are errors, assignments are validated."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)


class RewardConfig(Strict):
    """Per decision step: alive x (seconds elapsed / decision period), plus speed_weight x that
    fraction x the ego's mean speed over the step mapped from speed_range [m/s] to [0, 1]; a crash
    gives `collision` instead; `lane_change` is subtracted whenever the agent asks for a lane change
    (granted or masked), a margin like MOBIL's threshold so it asks only when the change pays. The
    paper's reward is alive = 1, collision = -1, speed_weight = 0, lane_change = 0."""

    alive: float = Field(1.0, ge=-MAX_REWARD, le=MAX_REWARD)
    collision: float = Field(-1.0, ge=-MAX_REWARD, le=MAX_REWARD)
    speed_weight: float = Field(0.0, ge=0, le=MAX_REWARD)
    speed_range: tuple[float, float] = (20.0, 30.0)
    lane_change: float = Field(0.0, ge=0, le=MAX_REWARD)

    @field_validator("speed_range")
    @classmethod
    def _ordered(cls, bounds: tuple[float, float]) -> tuple[float, float]:
        if not 0 <= bounds[0] < bounds[1] <= MAX_SPEED_RANGE:
            raise ValueError(
                f"must be (low, high) with 0 <= low < high <= {MAX_SPEED_RANGE:g}, got {list(bounds)}"
            )
        return bounds


class ValidationConfig(Strict):
    """The paper's real-time validation: short and long periods in environment steps."""

    short_every: int = Field(2_000, ge=1, le=MAX_STEPS)
    short_episodes: int = Field(3, ge=1, le=100_000)
    long_every: int = Field(10_000, ge=1, le=MAX_STEPS)
    long_episodes: int = Field(10, ge=1, le=100_000)
    seed: int = Field(100_000, ge=0, le=SEED_LIMIT - 1_000_000)


def checked_mix(mix: dict[str, float]) -> dict[str, float]:
    """`mix` unless a name is no scenario or a share is outside (0, MAX_SHARE] (ValueError)."""
    for name, share in mix.items():
        if name not in scenarios.names():
            raise ValueError(unknown_name("scenario", name, scenarios.names()))
        if not 0 < share <= MAX_SHARE:
            raise ValueError(
                f"scenario {name!r}: the share must be a number in (0, {MAX_SHARE:g}], got {share}"
            )
    return mix


ScenarioMix = Annotated[dict[str, float], AfterValidator(checked_mix)]
"""Named scenarios with their shares (relative weights)."""


EXPERTS = ("mobil", "rule", "lookahead", "oracle", *LEARNED_EXPERTS)
"""Agents whose decisions can be demonstrations: the classical baselines, the lookahead planner, the
oracle and a Q-network (deciding with `train.demonstrations.expert_model`)."""


def existing_model_file(path: str | None, expected: str = "") -> str | None:
    """`path` unless it names no file (ValueError saying what was `expected`)."""
    if path is not None and not Path(path).is_file():
        raise ValueError(f"no such model file {path}{expected}")
    return path


class DemonstrationConfig(Strict):
    """DQfD (Hester et al., 2018): `episodes` training episodes driven by `expert` (seeded from
    `seed`, a stream of its own) are recorded with n-step returns; `pretrain_steps` gradient steps
    on them alone precede the first episode of training, and afterwards `share` of every batch is
    drawn from them. On those rows a large-margin loss (weight `margin_weight`) keeps the expert's
    action `margin` above the others. The expert drives the worlds of `scenarios` (by default the
    training mix): an expert worth copying on some worlds only demonstrates there; `experts` names
    another expert for some of those worlds (a teacher per world: the one worth copying there)."""

    expert: Annotated[str, one_of("expert", EXPERTS)] = "mobil"
    experts: dict[str, Annotated[str, one_of("experts", EXPERTS)]] = Field(
        default_factory=dict,
        description="scenario -> the expert of its episodes instead of `expert` (a scenario the "
        "demonstrations are not drawn from has none)",
    )
    expert_model: str | None = Field(
        None,
        description="the model file a learned expert (ddqn, dqn) decides with (none: the agent's "
        "shipped file); in a config file, a name of a file beside it is that file",
    )
    episodes: int = Field(200, ge=1, le=100_000)
    pretrain_steps: int = Field(10_000, ge=0, le=10_000_000)
    share: float = Field(0.25, ge=0, lt=1)
    margin: float = Field(0.8, ge=0, le=MAX_REWARD)
    margin_weight: float = Field(1.0, ge=0, le=MAX_REWARD)
    seed: int = Field(200_000, ge=0, le=SEED_LIMIT - 1_000_000)
    scenarios: ScenarioMix = Field(
        default_factory=dict,
        description="the worlds the expert drives, with their shares (empty: the training mix): "
        "demonstrations only where the expert is the one to copy",
    )

    @field_validator("expert_model")
    @classmethod
    def _existing_model(cls, path: str | None) -> str | None:
        """The file, as an absolute path: the run's config.yaml names it from any directory."""
        if path is None:
            return None
        existing_model_file(path)
        return str(Path(path).resolve())

    @field_validator("experts")
    @classmethod
    def _named_scenarios(cls, experts: dict[str, str]) -> dict[str, str]:
        if unknown := [name for name in experts if name not in scenarios.names()]:
            raise ValueError(unknown_name("scenario", unknown[0], scenarios.names()))
        return experts

    @model_validator(mode="after")
    def _model_for_a_learned_expert(self) -> DemonstrationConfig:
        learned = self.learned_experts()
        if self.expert_model is not None and not learned:
            raise ValueError(f"expert_model: no learned expert ({', '.join(LEARNED_EXPERTS)}) is named")
        if len(learned) > 1:
            raise ValueError("experts: at most one learned expert, the one expert_model names")
        return self

    def named_experts(self) -> tuple[str, ...]:
        """Every expert named: `expert`, then those of `experts`, once each."""
        return tuple(dict.fromkeys([self.expert, *self.experts.values()]))

    def learned_experts(self) -> tuple[str, ...]:
        """The Q-networks among the experts named (at most one once validated)."""
        return tuple(name for name in self.named_experts() if name in LEARNED_EXPERTS)

    def expert_of(self, scenario: str | None) -> str:
        """The expert of an episode in `scenario`'s world."""
        return self.experts.get(scenario or "", self.expert)


class TrainConfig(Strict):
    """`drivestack train`: algorithm, budget, network, SB3 hyper-parameters, reward, validation."""

    algorithm: Annotated[LearnedAgentName, one_of("algorithm", LEARNED_AGENTS)] = "ddqn"
    steps: int = Field(50_000, ge=1, le=MAX_STEPS)
    envs: int = Field(
        1,
        ge=1,
        le=64,
        description="processes stepping the environments in parallel (DDQN / DQN): one per-world env "
        "each, or with train.worlds a shard of worlds / envs batched worlds each",
    )
    worlds: int | None = Field(
        None,
        ge=1,
        le=MAX_WORLDS,
        description="worlds stepped together as one batched env, each episode drawing its world of a "
        "train.scenarios mix as the per-world envs do: in the learner's process (train.envs 1) or "
        "split evenly over train.envs worker processes, the same run either way (DDQN / DQN; none: "
        "the per-world envs)",
    )
    replay_ratio: float = Field(
        1.0,
        gt=0,
        le=MAX_REPLAY_RATIO,
        description="gradient steps per decision collected (per train_freq decisions): each step of "
        "the N worlds or envs is followed by replay_ratio x N of them, a whole number",
    )
    scenarios: ScenarioMix = Field(
        default_factory=dict,
        description="a mix of named scenarios with their shares: each training and validation "
        "episode draws its world from it (empty: the run's own world)",
    )
    encoding: Annotated[Encoding, one_of("encoding", ENCODINGS)] = "observation"
    network: Annotated[str, one_of("network", tuple(NET_ARCHS))] = "shallow"
    learning_rate: float = Field(5e-4, gt=0, le=1)
    buffer_size: int = Field(50_000, ge=1, le=50_000_000)
    learning_starts: int = Field(1_000, ge=0, le=MAX_STEPS)
    batch_size: int = Field(64, ge=1, le=65_536)
    gamma: float = Field(0.95, gt=0, le=1)
    n_steps: int = Field(1, ge=1, le=20, description="n-step returns (SB3's NStepReplayBuffer)")
    train_freq: int = Field(1, ge=1, le=MAX_STEPS)
    target_update_interval: int = Field(500, ge=1, le=MAX_STEPS)
    exploration_fraction: float = Field(0.3, gt=0, le=1)
    exploration_initial_eps: float = Field(1.0, ge=0, le=1)
    exploration_final_eps: float = Field(0.05, ge=0, le=1)
    tabular_alpha: float = Field(0.1, gt=0, le=1)
    tabular_epsilon: float = Field(0.2, ge=0, le=1)
    checkpoint_every: int = Field(5_000, ge=1, le=MAX_STEPS)
    init_model: str | None = Field(
        None,
        description="a DDQN / DQN model file whose Q-network starts the training (fine-tuning), or "
        "'shipped' for the algorithm's shipped model; it must take this run's observations through "
        "the same network",
    )
    reward: RewardConfig = RewardConfig()
    validation: ValidationConfig = ValidationConfig()
    demonstrations: DemonstrationConfig | None = Field(
        None, description="an expert's episodes to pre-train on and keep learning from (ddqn only)"
    )
    mobil_prior: float = Field(
        0.0,
        ge=0,
        le=MAX_PRIOR,
        description="bonus [reward units] the greedy decision gives the lane change MOBIL proposes "
        "(ddqn only; in rollouts, validation and the model files written; 0: none)",
    )
    action_mask: bool = Field(
        False,
        description="the observation ends with the safety layer's permitted commands and the agent "
        "chooses among them, in acting, exploring and the Double-DQN target (ddqn only)",
    )

    members: int = Field(
        1,
        ge=1,
        le=MAX_MEMBERS,
        description="runs of this config trained one after the other, seeds `seed` to seed + members - 1, "
        "each in its own folder seed-S, then deciding together on the mean of their Q-values (an "
        "ensemble model file, `drivestack ensemble`; ddqn / dqn)",
    )
    member_jobs: int = Field(
        1,
        ge=1,
        le=MAX_MEMBERS,
        description="members trained at once, each in a process of its own (1: one after the other); "
        "each member is the run it is alone, bit for bit, its demonstrations recorded once for all; "
        "the replay buffers of all of them must fit in memory",
    )
    overlap: bool = Field(
        False,
        description="the gradient steps due after a step of the environments run while the env "
        "processes (train.envs >= 2) take the next step, learning from the transitions up to the "
        "step before: both cores busy, a run one step staler than without (ddqn only)",
    )

    @field_validator("init_model")
    @classmethod
    def _existing_model(cls, path: str | None) -> str | None:
        """'shipped', or the file as an absolute path: the run's config.yaml names it from any
        directory."""
        if path is None or path == "shipped":
            return path
        existing_model_file(path, " (a model file or 'shipped')")
        return str(Path(path).resolve())

    @model_validator(mode="after")
    def _one_env_for_tables(self) -> TrainConfig:
        if self.algorithm == "tabular" and self.envs > 1:
            raise ValueError("envs: tabular Q-learning steps one environment; use 1")
        if self.algorithm == "tabular" and self.init_model is not None:
            raise ValueError("init_model: tabular Q-learning starts from an empty table")
        if self.algorithm != "ddqn" and self.demonstrations is not None:
            raise ValueError("demonstrations: only the ddqn algorithm learns from them")
        if self.algorithm != "ddqn" and self.mobil_prior:
            raise ValueError("mobil_prior: only the ddqn algorithm decides with one")
        if self.algorithm != "ddqn" and self.action_mask:
            raise ValueError("action_mask: only the ddqn algorithm learns with one")
        if self.algorithm == "tabular" and self.members > 1:
            raise ValueError("members: an ensemble is of Q-networks (ddqn, dqn), not Q-tables")
        if self.algorithm != "ddqn" and self.overlap:
            raise ValueError("overlap: only the ddqn algorithm learns while its environments step")
        return self

    @model_validator(mode="after")
    def _batched_worlds_run_it(self) -> TrainConfig:
        if self.worlds is not None and (refusal := self._batch_refusal()):
            raise ValueError(f"worlds: {refusal}")
        steps = self.replay_ratio * self.parallel
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
            raise ValueError(
                f"replay_ratio: {self.replay_ratio:g} x {self.parallel} decisions a step must be a whole "
                "number of gradient steps, at least 1"
            )
        return self

    def _batch_refusal(self) -> str | None:
        """What batched worlds do not train (one line), or None."""
        if self.algorithm == "tabular":
            return "tabular Q-learning steps one environment; batched worlds train ddqn or dqn"
        if self.worlds and self.worlds % self.envs:
            return f"train.worlds {self.worlds} does not split evenly over train.envs {self.envs} processes"
        if self.encoding != "observation":
            return f"batched worlds encode train.encoding observation, not {self.encoding!r}"
        return None

    @property
    def parallel(self) -> int:
        """Decisions one step of the training env brings: its worlds or its envs."""
        return self.worlds or self.envs

    @property
    def gradient_steps(self) -> int:
        """Gradient steps after each step of the training env (`replay_ratio` x `parallel`)."""
        return round(self.replay_ratio * self.parallel)
