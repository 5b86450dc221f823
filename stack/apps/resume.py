"""What `run` and `compare` keep so that `--resume` can finish them: the resolved config written
when they start, and one journal of finished episodes per agent (`stack.runtime.files`). Light to
import: a refused `--resume` costs no simulator import."""

from __future__ import annotations

import hashlib
import importlib.util
import math
import sys
from pathlib import Path

from common.plugins import FILE_SPEC, MODULE_SPEC, file_safe
from records import child_seed
from stack.results.episode_result import EpisodeResult
from stack.runtime.files import JOURNAL, EpisodeJournal, write_text
from stack.runtime.owner import Owner, fingerprint, refusal
from stack.settings.history import unfingerprinted
from stack.settings.run import MAX_CONFIG_BYTES, RunConfig, config_text, printable

JOURNAL_ROW_BYTES = 2_000
"""Bytes one journaled episode takes at most (about 450 in practice): bounds what --resume reads."""


CODE_FILE = "code file: "
"""How config.yaml's header names a file whose content decides the episodes, with its digest."""


def resolved_config(configs: list[RunConfig], exclude: dict | None = None) -> str:
    """The config.yaml of a run or comparison of `configs`: the resolved config and, first, the
    agents and models (without the keys `exclude` names) and the digest of every plug-in and
    model file they load (`code_digests`), so `--resume` knows when one was edited."""
    agents = ", ".join(
        c.planner.agent + (f" ({c.planner.model})" if c.planner.model else "") for c in configs
    )
    return config_text(configs[0], f"the resolved config; agents: {agents}{code_files(configs)}", exclude)


def code_files(configs: list[RunConfig]) -> str:
    """The lines of a config.yaml header (each after a newline) naming every file `code_digests`
    finds for `configs`, with its digest: what `edited_file` compares against."""
    return "".join(f"\n{CODE_FILE}{path} sha256 {digest}" for path, digest in code_digests(configs).items())


def code_digests(configs: list[RunConfig]) -> dict[str, str]:
    """The SHA-256 of each file besides the config that decides the episodes of `configs`: the
    agents' and controllers' plug-in files (`file.py:Class`, and the module file of a
    `module:Class`) and the model files given, by path. A file that cannot be read or found is
    left out (the run's own checks name it)."""
    paths: list[str] = []
    for config in configs:
        for spec in (config.planner.agent, config.controller.type):
            if match := FILE_SPEC.fullmatch(spec):
                paths.append(match["file"])
            elif (match := MODULE_SPEC.fullmatch(spec)) and (origin := module_file(match["module"])):
                paths.append(origin)
        if config.planner.model is not None:
            paths.append(str(config.planner.model))
    digests = {}
    for path in dict.fromkeys(paths):
        try:
            with open(path, "rb") as handle:
                digests[path] = hashlib.file_digest(handle, "sha256").hexdigest()
        except OSError:
            continue
    return digests


def module_file(module: str) -> str | None:
    """The source file a plug-in's `module` is loaded from, or None (not found, or not a file)."""
    try:
        found = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        return None
    return found.origin if found is not None and found.has_location and found.origin else None


def edited_code(configs: list[RunConfig], out: Path) -> str | None:
    """Why `--resume` into `out` must not go on (one line) when a plug-in or model file that its
    config.yaml records was edited since the run started (its episodes would mix two versions of
    the code), or None."""
    if (edited := edited_file(configs, out)) is not None:
        return (
            f"--resume: {edited} was edited since the run started (its episodes would mix two "
            "versions); restore it, or run again without --resume"
        )
    return None


def edited_file(configs: list[RunConfig], out: Path) -> str | None:
    """The first plug-in or model file of `configs` that `out`/config.yaml records (`code_files`)
    and whose content has changed since, or None (none changed, or no such config.yaml)."""
    stored = out / "config.yaml"
    try:
        if not stored.is_file() or stored.stat().st_size > MAX_CONFIG_BYTES:
            return None
        header = stored.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    recorded = {}
    for line in header:
        if not line.startswith("#"):
            break
        path, _, digest = line.removeprefix("# ").removeprefix(CODE_FILE).rpartition(" sha256 ")
        if line.startswith(f"# {CODE_FILE}") and path:
            recorded[path] = digest
    now = code_digests(configs)
    return next((path for path, digest in recorded.items() if path in now and now[path] != digest), None)


def run_owner(configs: list[RunConfig], command: str) -> Owner:
    """The owner a `run` or `compare` of `configs` records in its results folder: the fingerprint
    of what decides its results (the `unfingerprinted` keys left out: `--resume` may batch
    differently, and a folder from before a key was added resumes)."""
    return Owner(command, fingerprint(resolved_config(configs, unfingerprinted(configs[0]))))


def journal_of(config: RunConfig, out: Path) -> EpisodeJournal:
    """Where the finished episodes of `config`'s agent are kept while a run or comparison goes on."""
    return EpisodeJournal(out / f"{file_safe(config.planner.agent)}.{JOURNAL}")


def started(
    configs: list[RunConfig], out: Path, done: dict[str, list[EpisodeResult]] | None
) -> list[EpisodeJournal]:
    """Write `out`/config.yaml and return each agent's journal, holding exactly the episodes
    resumed (`done`; none on a fresh start, which empties journals an earlier run left there).
    Every journal exists from now on, so a run stopped before its first episode can be resumed."""
    write_text(out / "config.yaml", resolved_config(configs))
    journals = [journal_of(config, out) for config in configs]
    for config, journal in zip(configs, journals, strict=True):
        journal.keep((done or {}).get(config.planner.agent, []))
    return journals


def resumable(configs: list[RunConfig], out: Path, command: str) -> dict[str, list[EpisodeResult]]:
    """Per agent, the episodes the interrupted `command` (run or compare) in `out` finished: the
    folder must be that command's (`stack.runtime.owner`), its config.yaml the one `configs` write,
    and each journaled episode one of theirs (`journaled`). ValueError, naming the file, when `out`
    holds another run, none, or no journal (a finished run: nothing to resume)."""
    if why := edited_code(configs, out) or refusal(out, run_owner(configs, command), resuming=True):
        raise ValueError(why)
    stored, expected = out / "config.yaml", resolved_config(configs).encode()
    if not stored.is_file():
        raise ValueError(f"--resume: {out} holds no run to resume (no config.yaml)")
    if stored.stat().st_size != len(expected) or stored.read_bytes() != expected:
        raise ValueError(
            f"--resume: {stored} is another run's (other agents, models or config); "
            "resume with the arguments that started it"
        )
    journals = [journal_of(config, out) for config in configs]
    if not any(journal.path.is_file() for journal in journals):
        raise ValueError(f"--resume: {out} holds no unfinished episodes (no journal); nothing to resume")
    return {
        config.planner.agent: journaled(config, journal)
        for config, journal in zip(configs, journals, strict=True)
    }


def journaled(config: RunConfig, journal: EpisodeJournal) -> list[EpisodeResult]:
    """The episodes of `config` that `journal` holds; a line that is not one (damaged, cut short,
    a value out of range, another run's episode) is dropped with a one-line warning naming the
    file, and that episode runs again. A journal an earlier version wrote (its episodes lack fields
    measured since) is refused: ValueError, in one line."""
    episodes: dict[int, EpisodeResult] = {}
    dropped = []
    for number, row in enumerate(journal.lines(JOURNAL_ROW_BYTES * config.episodes), start=1):
        if row is not None and (missing := EpisodeResult.missing(row)):
            raise ValueError(
                f"--resume: {journal.path} was written by an earlier drivestack (its episodes lack "
                f"{', '.join(missing)}); run again without --resume"
            )
        episode = EpisodeResult.from_row(row) if row is not None and in_range(row) else None
        if episode is None or not belongs(episode, config):
            dropped.append(number)
        else:
            episodes[episode.episode] = episode
    if dropped:
        lines = ", ".join(map(str, dropped[:5])) + (" ..." if len(dropped) > 5 else "")
        warn(
            f"{journal.path}: dropped line {lines} (not a finished episode of this run: damaged, "
            "cut short or out of range); its episode runs again"
        )
    return list(episodes.values())


def in_range(row: dict[str, object]) -> bool:
    """Whether every number in a journaled `row` is one an episode can record: finite, and
    counts (integers) not negative. Checked by type, so fields added later are covered."""
    numbers = [v for v in row.values() if isinstance(v, int | float) and not isinstance(v, bool)]
    return all(math.isfinite(v) and (v >= 0 or not isinstance(v, int)) for v in numbers)


def belongs(episode: EpisodeResult, config: RunConfig) -> bool:
    """Whether `episode` is one of `config`'s: its number in range, its seed the one it gets."""
    return 0 <= episode.episode < config.episodes and episode.seed == child_seed(config.seed, episode.episode)


def warn(message: str) -> None:
    """`message` as one warning line on stderr."""
    print(f"warning: {printable(message)}", file=sys.stderr)
