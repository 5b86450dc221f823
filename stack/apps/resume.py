"""What `run` and `compare` keep so that `--resume` can finish them: the resolved config written
when they start, and one journal of finished episodes per agent (`stack.core.files`). Light to
import: a refused `--resume` costs no simulator import."""

from __future__ import annotations

from pathlib import Path

from records import child_seed
from records.plugins import file_safe
from stack.core.config import RunConfig, config_text
from stack.core.files import JOURNAL, EpisodeJournal, write_text
from stack.core.metrics import EpisodeResult

JOURNAL_ROW_BYTES = 2_000
"""Bytes one journaled episode takes at most (about 450 in practice): bounds what --resume reads."""


def resolved_config(configs: list[RunConfig]) -> str:
    """The config.yaml of a run or comparison of `configs`: the resolved config and, first, the
    agents and models."""
    agents = ", ".join(
        c.planner.agent + (f" ({c.planner.model})" if c.planner.model else "") for c in configs
    )
    return config_text(configs[0], f"the resolved config; agents: {agents}")


def journal_of(config: RunConfig, out: Path) -> EpisodeJournal:
    """Where the finished episodes of `config`'s agent are kept while a run or comparison goes on."""
    return EpisodeJournal(out / f"{file_safe(config.planner.agent)}.{JOURNAL}")


def started(configs: list[RunConfig], out: Path, resuming: bool) -> list[EpisodeJournal]:
    """Write `out`/config.yaml and return each agent's journal; a fresh start (not `resuming`)
    empties journals an earlier interrupted run left there."""
    write_text(out / "config.yaml", resolved_config(configs))
    journals = [journal_of(config, out) for config in configs]
    for journal in journals if not resuming else []:
        journal.discard()
    return journals


def resumable(configs: list[RunConfig], out: Path) -> dict[str, list[EpisodeResult]]:
    """Per agent, the episodes the interrupted run or comparison in `out` finished: its
    config.yaml must be the one `configs` write, and each journaled episode one of theirs (its
    number in range, its seed the one that number gets). ValueError, naming the file, when `out`
    holds another run, none, or no journal (a finished run: nothing to resume)."""
    stored, expected = out / "config.yaml", resolved_config(configs)
    if not stored.is_file():
        raise ValueError(f"--resume: {out} holds no run to resume (no config.yaml)")
    if stored.stat().st_size != len(expected.encode()) or stored.read_text() != expected:
        raise ValueError(
            f"--resume: {stored} is another run's (other agents, models or config); "
            "resume with the arguments that started it"
        )
    journals = [journal_of(config, out) for config in configs]
    if not any(journal.path.is_file() for journal in journals):
        raise ValueError(f"--resume: {out} holds no unfinished episodes (no journal); nothing to resume")
    done: dict[str, list[EpisodeResult]] = {}
    for config, journal in zip(configs, journals, strict=True):
        rows = journal.rows(JOURNAL_ROW_BYTES * config.episodes)
        episodes = {e.episode: e for e in map(EpisodeResult.from_row, rows) if e is not None}
        done[config.planner.agent] = [
            e
            for e in episodes.values()
            if 0 <= e.episode < config.episodes and e.seed == child_seed(config.seed, e.episode)
        ]
    return done
