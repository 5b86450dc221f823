"""How each field of an episode's record (`stack.results.episode_result.EpisodeResult`) is reported, declared
once on the field (`declared(...)` as its metadata) and read by every report:

- its unit and its `section` (collisions, safety, progress, decisions, comfort, compute): the
  summary, `drivestack run`'s summary table and compare's tables list fields section by section,
  in the record's order within a section;
- its `summary` entries: summary.json's keys made from it over a run's episodes (mean, total,
  rate, largest, smallest, median, or a function of the episodes for the entries that combine
  fields, such as accuracy);
- its `rows` in `drivestack run`'s summary table (a label and a format over the summary);
- its `interval`: the 95 % interval `compare` reports (of the mean, or of the rate of a flag), and
  its `columns` in compare's two tables (agents, safety);
- whether it is measured in wall-clock time (`timing`: never in episodes.csv, never part of a
  result's identity);
- its `measure`, for a field measured from the samples every recorder keeps: a function of the
  episode's `stack.results.episode_measures.EpisodeSamples`, which both paths run.

Adding a metric of those samples is declaring its field with these and its measurer; the files,
tables and both paths follow.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import Field, dataclass, fields
from string import Formatter
from typing import Any, Literal, get_args

import numpy as np

Section = Literal["episode", "collisions", "safety", "progress", "decisions", "comfort", "compute"]
SECTIONS: tuple[Section, ...] = get_args(Section)
"""The order in which the reports list the sections."""

Aggregate = Callable[[list[Any], Sequence[Any]], object]
"""A summary entry from one field's values over a run's episodes (and the episodes themselves, for
entries that combine fields)."""


def mean(values: list[Any], episodes: Sequence[Any]) -> float:
    """The mean over episodes."""
    return float(np.mean(values))


def total(values: list[Any], episodes: Sequence[Any]) -> int:
    """The sum over episodes (of counts, or of flags: the episodes that raised it)."""
    return int(sum(values))


def rate(values: list[Any], episodes: Sequence[Any]) -> float:
    """The share of episodes that raised a flag."""
    return sum(values) / len(values)


def largest(values: list[Any], episodes: Sequence[Any]) -> float:
    """The worst (largest) episode's value."""
    return float(max(values))


def smallest(values: list[Any], episodes: Sequence[Any]) -> float:
    """The worst (smallest) episode's value."""
    return float(min(values))


def median(values: list[Any], episodes: Sequence[Any]) -> float:
    """The median over episodes."""
    return float(np.median(values))


@dataclass(frozen=True)
class Summarized:
    """One summary.json entry: `key`, made from the field by `over`."""

    key: str
    over: Aggregate


@dataclass(frozen=True)
class SummaryRow:
    """A row of `drivestack run`'s summary table: `label`, and `shown`, a format string over the
    summary ("{min_ttc_s:.2f} s"); "n/a" when an entry it shows is None."""

    label: str
    shown: str

    def text(self, summary: Mapping[str, Any]) -> str:
        if any(summary.get(key) is None for key in _names(self.shown)):
            return "n/a"
        return self.shown.format_map(summary)


def _names(shown: str) -> list[str]:
    """The summary entries the format `shown` names."""
    return [name.split(".")[0] for _, name, _, _ in Formatter().parse(shown) if name]


@dataclass(frozen=True)
class CompareInterval:
    """The 95 % interval `compare` reports as `key`: of the field's mean over episodes, or of the
    rate of episodes that raised it (a flag)."""

    key: str
    kind: Literal["mean", "rate"]


Table = Literal["agents", "safety", "episodes"]
"""compare's tables (the agents' headline metrics, and their safety metrics) and run's table of
episodes."""


@dataclass(frozen=True)
class Column:
    """A column of one of the tables: its `header` and its cell, by `cell` from an agent's row of
    comparison.json (its summary and `intervals`) in compare's, from an episode's `row()` in run's."""

    table: Table
    header: str
    cell: Callable[[Mapping[str, Any]], str]


@dataclass(frozen=True)
class Reported:
    """How one field is reported (module docstring)."""

    unit: str
    section: Section
    summary: tuple[Summarized, ...] = ()
    rows: tuple[SummaryRow, ...] = ()
    interval: CompareInterval | None = None
    columns: tuple[Column, ...] = ()
    timing: bool = False
    measure: Callable[[Any], object] | None = None


def declared(
    unit: str,
    section: Section,
    summary: tuple[Summarized, ...] = (),
    rows: tuple[SummaryRow, ...] = (),
    interval: CompareInterval | None = None,
    columns: tuple[Column, ...] = (),
    timing: bool = False,
    measure: Callable[[Any], object] | None = None,
) -> dict[str, Reported]:
    """A field's metadata: how it is reported and, for a field measured from the recorded samples,
    how it is measured (`Reported`)."""
    return {"reported": Reported(unit, section, summary, rows, interval, columns, timing, measure)}


def record_fields(record: Any) -> dict[str, Any]:
    """The fields of the dataclass instance `record` by name, not copied (to build a record from
    the parts that measured it)."""
    return {f.name: getattr(record, f.name) for f in fields(record)}


def reported(record: type) -> list[tuple[Field[Any], Reported]]:
    """The declared fields of the dataclass `record` with their declarations, section by section,
    in the record's order within a section."""
    found = [(f, f.metadata["reported"]) for f in fields(record) if "reported" in f.metadata]
    return sorted(found, key=lambda pair: SECTIONS.index(pair[1].section))


def timing_fields(record: type) -> tuple[str, ...]:
    """The fields of `record` measured in wall-clock time."""
    return tuple(f.name for f, how in reported(record) if how.timing)


def summary_entries(record: type, episodes: Sequence[Any]) -> dict[str, object]:
    """Every summary entry of `record`'s fields over `episodes`, in the reports' order."""
    entries: dict[str, object] = {}
    for f, how in reported(record):
        values = [getattr(episode, f.name) for episode in episodes]
        for entry in how.summary:
            entries[entry.key] = entry.over(values, episodes)
    return entries


def summary_rows(record: type, summary: Mapping[str, Any]) -> Iterator[tuple[str, str]]:
    """(label, text) of every row of `drivestack run`'s summary table, in the reports' order."""
    for _, how in reported(record):
        for row in how.rows:
            yield row.label, row.text(summary)


def intervals(record: type) -> list[tuple[str, CompareInterval]]:
    """(field, interval) of every field `compare` reports an interval of: rates first, then means,
    each in the order of compare's tables (agents, then safety), then the rest."""
    order: dict[str, int] = {}
    for table in ("agents", "safety"):
        for f, how in reported(record):
            if any(column.table == table for column in how.columns):
                order.setdefault(f.name, len(order))
    found = [(f.name, how.interval) for f, how in reported(record) if how.interval is not None]
    return sorted(found, key=lambda pair: (pair[1].kind != "rate", order.get(pair[0], len(order))))


def columns(record: type, table: Table) -> list[Column]:
    """The columns of `table`, in the reports' order."""
    return [column for _, how in reported(record) for column in how.columns if column.table == table]


def interval_text(interval: Sequence[float], scale: float = 1.0, digits: int = 2, sign: str = "") -> str:
    """`value [low, high]`, each times `scale`, with `digits` decimals (`sign`: "+" to sign them)."""
    value, low, high = (scale * v for v in interval)
    return f"{value:{sign}.{digits}f} [{low:{sign}.{digits}f}, {high:{sign}.{digits}f}]"


def interval_cell(key: str, scale: float = 1.0, digits: int = 2) -> Callable[[Mapping[str, Any]], str]:
    """A compare cell: the interval `key` of the agent's row."""
    return lambda row: interval_text(row["intervals"][key], scale, digits)


def episode_cell(shown: str) -> Callable[[Mapping[str, Any]], str]:
    """A cell of run's table of episodes: the episode's fields by the format `shown`."""
    return lambda row: shown.format_map(row)


def summary_cell(shown: str) -> Callable[[Mapping[str, Any]], str]:
    """A compare cell: summary entries of the agent's row by the format `shown` ("n/a" for None)."""
    return lambda row: SummaryRow("", shown).text(row)
