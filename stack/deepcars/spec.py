"""What a DeepCars reproduction is made of: the rule sets, the step budgets and the table's rows.

Two rule sets. The paper's text (section 4.1): a 9-row line of sight and a fixed epsilon = 0.2 for
the tabular learner. The authors' public code (github.com/MajidMoghadam2006/
deepcars-reinforcement-learning: `DeepCars.py` has `MaxCarsInLane = 5`, so its state sees rows
0-3; `Train_DeepCars_DQN.py` starts at epsilon 1.0 and multiplies it by `epsilon_decay = 0.995`
every training step down to `epsilon_min = 0.01`): a 4-row line of sight and less and less
exploration (the repository trains no tabular agent: its DQN script's schedule is applied to the
tabular learner). Only the line of sight and the tabular exploration differ; the rest (the
paper's reward +1 / -1, where the public code gives -100 for a collision; one car spawned per step;
gamma, alpha; the DQN rows' own exploration) is shared.
The budgets (`FULL`: the paper's; `QUICK`: a smoke run of the whole table) and `Row`, one line of
results.md, live here too. No heavy imports: the CLI checks `--variant` against `RULES` before
any training code loads, and `report` reads rows without the training code.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Rules:
    """A DeepCars rule set: the world's `line_of_sight` [rows, the ego's row included] and the
    tabular learner's epsilon, `epsilon_start` multiplied by `epsilon_decay` after every training
    step and never below `epsilon_min`."""

    name: str
    line_of_sight: int
    epsilon_start: float
    epsilon_decay: float
    epsilon_min: float

    def epsilon_after(self, steps: int) -> float:
        """The exploration rate after `steps` training steps (for tests and the docs)."""
        return max(self.epsilon_min, self.epsilon_start * self.epsilon_decay**steps)

    @property
    def summary(self) -> str:
        """One line for results.md."""
        exploration = f"epsilon {self.epsilon_start:g}"
        if self.epsilon_decay != 1:
            exploration += f" x{self.epsilon_decay:g} per step, floor {self.epsilon_min:g}"
        return f"{self.name}: {self.line_of_sight}-row line of sight, tabular {exploration}"


PAPER_RULES = Rules("paper", line_of_sight=9, epsilon_start=0.2, epsilon_decay=1.0, epsilon_min=0.2)
PUBLIC_RULES = Rules("public", line_of_sight=4, epsilon_start=1.0, epsilon_decay=0.995, epsilon_min=0.01)
RULES = {rules.name: rules for rules in (PAPER_RULES, PUBLIC_RULES)}
"""`drivestack reproduce deepcars --variant` names (`all`: both, one block of rows each)."""
VARIANTS = tuple(RULES)

PAPER = {
    "tabular": {"train": 98.28, "eval": 99.14},
    "dqn": {"eval": 100.0},
    "ddqn": {"eval": 100.0},
}
"""The paper's accuracies [%] (Moghadam & Elkaim 2019, section 4)."""

PAPER_NETWORKS = ("shallow", "medium", "deep", "16", "16x16")
"""The MLPs of the DQN and DDQN rows (`planner.networks.NET_ARCHS`): the paper's sizes and the two
small ones, not the highway grid's lane network, which reads lanes DeepCars' grid does not have."""


@dataclass(frozen=True)
class Budget:
    """Environment steps for training, validation and evaluation of every row."""

    tabular_steps: int = 50_000
    tabular_long_steps: int = 1_000_000
    dqn_max_steps: int = 500_000
    eval_steps: int = 100_000
    short_every: int = 5_000
    long_every: int = 25_000
    short_episodes: int = 3
    long_episodes: int = 10


FULL = Budget()
QUICK = Budget(
    tabular_steps=5_000,
    tabular_long_steps=20_000,
    dqn_max_steps=2_000,
    eval_steps=10_000,
    short_every=1_000,
    long_every=2_000,
    short_episodes=1,
    long_episodes=2,
)


@dataclass
class Row:
    """One line of the table; accuracies in %, `paper_*` the paper's numbers where it gives them;
    `rules` names the `Rules` it ran under."""

    rules: str
    agent: str
    network: str
    training_steps: int
    train_accuracy: float | None
    eval_accuracy: float
    eval_collisions: int
    eval_passed: int
    wall_time_s: float
    paper_train: float | None
    paper_eval: float | None
