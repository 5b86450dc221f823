"""The record of one closed-loop episode (`EpisodeResult`) and the run's summary made from its
episodes (`summarize`). Every measured field declares its unit and how the reports show it
(`stack.results.episode_fields`): summary.json, episodes.csv, timings.csv, the journal of a run that
can be resumed, the tables of `drivestack run` and `compare` and compare's intervals follow from
these declarations, so a new metric is its computation plus its field here."""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields
from typing import Any

from perception.grid import OccupancyGrid
from records import WorldState
from stack.results import episode_measures as measures
from stack.results.episode_fields import (
    Column,
    CompareInterval,
    Summarized,
    SummaryRow,
    declared,
    episode_cell,
    interval_cell,
    largest,
    mean,
    median,
    rate,
    smallest,
    summary_cell,
    summary_entries,
    timing_fields,
    total,
)

TTC_CAP_S = 99.0
"""The minimum TTC an episode reports when nothing ever closed in on a leader [s]."""


def _by_cause(cause: str, label: str) -> dict:
    """The declaration of the count of emergency brakings attributed to `cause`
    (`stack.fault.emergency_causes`), shown as `label`."""
    key = f"emergency_brakings_{cause}"
    return declared(
        "count",
        "safety",
        summary=(Summarized(key, mean),),
        rows=(SummaryRow(f"  of which {label} / episode", f"{{{key}:.2f}}"),),
        interval=CompareInterval(key, "mean"),
        columns=(Column("safety", f"AEB {label} / ep", interval_cell(key)),),
    )


@dataclass(frozen=True)
class EpisodeResult:
    """One closed-loop episode; `trace` holds per-tick time [s], speed [m/s] and lateral offset [m].
    Each measured field declares its unit and how the reports show it (`stack.results.episode_fields`):
    summary.json, episodes.csv, timings.csv, the tables of `run` and `compare` and compare's
    intervals are made from these declarations."""

    episode: int = field(
        metadata=declared("", "episode", columns=(Column("episodes", "episode", episode_cell("{episode}")),))
    )
    seed: int = field(
        metadata=declared("", "episode", columns=(Column("episodes", "seed", episode_cell("{seed}")),))
    )
    steps: int = field(metadata=declared("control ticks", "episode", measure=measures.steps))
    duration_s: float = field(metadata=declared("s", "episode", measure=measures.duration_s))
    crashed: bool = field(
        metadata=declared(
            "flag",
            "collisions",
            summary=(Summarized("collisions", total), Summarized("collision_rate", rate)),
            rows=(SummaryRow("collision rate", "{collision_rate:.1%} ({collisions})"),),
            interval=CompareInterval("collision_rate", "rate"),
            columns=(
                Column("episodes", "crashed", lambda row: "yes" if row["crashed"] else "no"),
                Column("agents", "collision rate %", interval_cell("collision_rate", 100, 1)),
            ),
        )
    )
    passed_cars: int = field(
        metadata=declared(
            "vehicles",
            "progress",
            measure=measures.passed_cars,
            summary=(Summarized("passed_cars", total), Summarized("accuracy", measures.accuracy)),
            rows=(SummaryRow("accuracy", "{accuracy:.2f} %"), SummaryRow("passed cars", "{passed_cars}")),
            columns=(
                Column("episodes", "passed", episode_cell("{passed_cars}")),
                Column("agents", "accuracy %", summary_cell("{accuracy:.2f}")),
            ),
        )
    )
    lane_changes: int = field(
        metadata=declared(
            "count",
            "decisions",
            summary=(Summarized("lane_changes", mean),),
            rows=(SummaryRow("lane changes / episode", "{lane_changes:.2f}"),),
            interval=CompareInterval("lane_changes", "mean"),
            columns=(
                Column("episodes", "lane changes", episode_cell("{lane_changes}")),
                Column("agents", "lane changes / ep", interval_cell("lane_changes")),
            ),
        )
    )
    mean_speed: float = field(
        metadata=declared(
            "m/s",
            "progress",
            measure=measures.mean_speed,
            summary=(Summarized("mean_speed", mean),),
            rows=(SummaryRow("mean speed", "{mean_speed:.2f} m/s"),),
            interval=CompareInterval("mean_speed", "mean"),
            columns=(
                Column("episodes", "mean speed [m/s]", episode_cell("{mean_speed:.2f}")),
                Column("agents", "mean speed m/s", interval_cell("mean_speed")),
            ),
        )
    )
    peak_lat_accel: float = field(
        metadata=declared(
            "m/s^2",
            "comfort",
            measure=measures.peak_lat_accel,
            summary=(Summarized("peak_lat_accel", largest),),
            columns=(Column("episodes", "peak |a_y| [m/s²]", episode_cell("{peak_lat_accel:.2f}")),),
        )
    )
    peak_lat_jerk: float = field(
        metadata=declared(
            "m/s^3",
            "comfort",
            measure=measures.peak_lat_jerk,
            summary=(Summarized("peak_lat_jerk", largest),),
            columns=(Column("episodes", "peak jerk [m/s³]", episode_cell("{peak_lat_jerk:.2f}")),),
        )
    )
    masked_commands: int = field(
        default=0,
        metadata=declared(
            "count",
            "decisions",
            summary=(Summarized("masked_commands", mean),),
            interval=CompareInterval("masked_commands", "mean"),
            columns=(Column("agents", "masked / ep", interval_cell("masked_commands")),),
        ),
    )
    aborted_changes: int = field(
        default=0,
        metadata=declared(
            "count",
            "decisions",
            summary=(Summarized("aborted_changes", mean),),
            interval=CompareInterval("aborted_changes", "mean"),
            columns=(Column("agents", "aborted / ep", interval_cell("aborted_changes")),),
        ),
    )
    fallback_decisions: int = field(
        default=0,
        metadata=declared(
            "count",
            "decisions",
            summary=(Summarized("fallback_decisions", mean),),
            rows=(SummaryRow("fallback decisions / episode", "{fallback_decisions:.2f}"),),
            interval=CompareInterval("fallback_decisions", "mean"),
            columns=(
                Column("episodes", "fallback", episode_cell("{fallback_decisions}")),
                Column("agents", "fallback / ep", interval_cell("fallback_decisions")),
            ),
        ),
    )
    mpc_fallbacks: int = field(
        default=0,
        metadata=declared(
            "count",
            "compute",
            summary=(Summarized("mpc_fallbacks", total),),
            rows=(SummaryRow("MPC fallbacks", "{mpc_fallbacks}"),),
        ),
    )
    road_departure: bool = field(
        default=False,
        metadata=declared(
            "flag",
            "safety",
            summary=(Summarized("road_departures", total), Summarized("failures", measures.failures)),
            rows=(SummaryRow("road departures", "{road_departures}"),),
            interval=CompareInterval("road_departure_rate", "rate"),
            columns=(
                Column("episodes", "off road", lambda row: "yes" if row["road_departure"] else "no"),
                Column("safety", "road departures %", interval_cell("road_departure_rate", 100, 1)),
            ),
        ),
    )
    at_fault_collision: bool = field(
        default=False,
        metadata=declared(
            "flag",
            "collisions",
            summary=(
                Summarized("at_fault_collisions", total),
                Summarized("not_at_fault_collisions", measures.not_at_fault),
            ),
            rows=(
                SummaryRow("at fault / not at fault", "{at_fault_collisions} / {not_at_fault_collisions}"),
            ),
            interval=CompareInterval("at_fault_rate", "rate"),
            columns=(
                Column("safety", "at-fault collisions %", interval_cell("at_fault_rate", 100, 1)),
                Column("safety", "not at fault", summary_cell("{not_at_fault_collisions}")),
            ),
        ),
    )
    collision_kind: str = field(
        default="",
        metadata=declared(
            "",
            "collisions",
            columns=(
                Column(
                    "episodes",
                    "fault",
                    lambda row: (
                        row["collision_kind"]
                        + (f" ({row['fault_reason']})" if row["fault_reason"] else "")
                        + (" (at fault)" if row["at_fault_collision"] else "")
                    ),
                ),
            ),
        ),
    )
    fault_reason: str = field(default="", metadata=declared("", "collisions"))
    """Why the collision is or is not the ego's fault, as R157 decides preventability
    (`stack.fault.preventability`): "cut-in not preventable", "leader braking preventable", "own lane
    change", ...; empty without a collision."""
    min_ttc_s: float = field(
        default=TTC_CAP_S,
        metadata=declared(
            "s",
            "safety",
            summary=(Summarized("min_ttc_s", smallest),),
            rows=(SummaryRow("min time to collision", "{min_ttc_s:.2f} s"),),
            columns=(
                Column("episodes", "min TTC [s]", episode_cell("{min_ttc_s:.1f}")),
                Column("safety", "min TTC s", summary_cell("{min_ttc_s:.2f}")),
            ),
        ),
    )
    time_below_min_distance_s: float = field(
        default=0.0,
        metadata=declared(
            "s",
            "safety",
            summary=(Summarized("time_below_min_distance_s", mean),),
            rows=(SummaryRow("time below R157 d_min / episode", "{time_below_min_distance_s:.2f} s"),),
            interval=CompareInterval("time_below_min_distance_s", "mean"),
            columns=(
                Column("safety", "below R157 d_min s / ep", interval_cell("time_below_min_distance_s")),
            ),
        ),
    )
    emergency_brakings: int = field(
        default=0,
        metadata=declared(
            "count",
            "safety",
            summary=(Summarized("emergency_brakings", mean),),
            rows=(SummaryRow("emergency brakings / episode", "{emergency_brakings:.2f}"),),
            interval=CompareInterval("emergency_brakings", "mean"),
            columns=(
                Column("episodes", "AEB", episode_cell("{emergency_brakings}")),
                Column("safety", "emergency brakings / ep", interval_cell("emergency_brakings")),
            ),
        ),
    )
    emergency_brakings_cut_in: int = field(default=0, metadata=_by_cause("cut_in", "cut-in"))
    emergency_brakings_leader_braking: int = field(
        default=0, metadata=_by_cause("leader_braking", "leader braking")
    )
    emergency_brakings_own_lane_change: int = field(
        default=0,
        metadata=_by_cause("own_lane_change", "own lane change"),
    )
    emergency_brakings_closing_in: int = field(default=0, metadata=_by_cause("closing_in", "closing in"))
    emergency_brakings_phantom: int = field(default=0, metadata=_by_cause("phantom", "phantom"))
    longest_standstill_s: float = field(
        default=0.0,
        metadata=declared(
            "s",
            "safety",
            measure=measures.longest_standstill_s,
            summary=(Summarized("longest_standstill_s", mean),),
            rows=(SummaryRow("longest standstill / episode", "{longest_standstill_s:.2f} s"),),
            interval=CompareInterval("longest_standstill_s", "mean"),
            columns=(Column("safety", "longest standstill s / ep", interval_cell("longest_standstill_s")),),
        ),
    )
    time_below_ttc_floor_s: float = field(default=0.0, metadata=declared("s", "safety"))
    solve_ms_p50: float = field(
        default=0.0,
        compare=False,
        metadata=declared(
            "ms",
            "compute",
            summary=(Summarized("solve_ms_p50", median),),
            rows=(SummaryRow("control compute p50 / p95", "{solve_ms_p50:.2f} / {solve_ms_p95:.2f} ms"),),
            timing=True,
        ),
    )
    solve_ms_p95: float = field(
        default=0.0,
        compare=False,
        metadata=declared("ms", "compute", summary=(Summarized("solve_ms_p95", largest),), timing=True),
    )
    time_in_leftmost_lane_s: float = field(
        default=0.0,
        metadata=declared(
            "s",
            "decisions",
            measure=measures.time_in_leftmost_lane_s,
            summary=(Summarized("time_in_leftmost_lane_s", mean),),
            rows=(SummaryRow("time in the leftmost lane / episode", "{time_in_leftmost_lane_s:.2f} s"),),
            interval=CompareInterval("time_in_leftmost_lane_s", "mean"),
            columns=(Column("agents", "leftmost lane s / ep", interval_cell("time_in_leftmost_lane_s")),),
        ),
    )
    trace: dict[str, list[float]] = field(default_factory=dict, repr=False)
    snapshot: tuple[WorldState, OccupancyGrid] | None = field(default=None, repr=False, compare=False)

    def row(self) -> dict:
        """The flat record (no traces, no snapshot): a journal line."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in _UNRECORDED}

    def outcome_row(self) -> dict:
        """`row()` without its wall-clock fields: an episodes.csv line, the same on every rerun."""
        return {name: value for name, value in self.row().items() if name not in TIMING_FIELDS}

    def timing_row(self) -> dict:
        """The episode, its seed and its wall-clock fields: a timings.csv line."""
        return {"episode": self.episode, "seed": self.seed} | {
            name: getattr(self, name) for name in TIMING_FIELDS
        }

    @classmethod
    def from_row(cls, row: dict[str, Any]) -> EpisodeResult | None:
        """The episode `row()` recorded, or None when `row` is not one (other keys, a value not of
        its field's type)."""
        kinds = {"int": int, "bool": bool, "float": int | float, "str": str}
        typed = {f.name: kinds[str(f.type)] for f in fields(cls) if f.name not in _UNRECORDED}
        if sorted(row) != sorted(typed) or not all(isinstance(row[n], kind) for n, kind in typed.items()):
            return None
        return cls(**row)

    @classmethod
    def missing(cls, row: dict[str, Any]) -> list[str]:
        """The fields `row` lacks when it is otherwise an episode's: a row an earlier version
        journaled, before those fields were measured (each has a default, and with the defaults
        the row is one); [] for any other row."""
        absent = {f.name: f.default for f in fields(cls) if f.name not in row and f.name not in _UNRECORDED}
        if not absent or MISSING in absent.values() or cls.from_row(row | absent) is None:
            return []
        return list(absent)


_UNRECORDED = ("trace", "snapshot")
"""The fields `row()` leaves out."""


TIMING_FIELDS = timing_fields(EpisodeResult)
"""Summary and episode fields measured in wall-clock time: never part of a result's identity."""


STEPPING_FIELDS = ("stepping", "stepping_reason")
"""How a run's worlds were stepped (batched or one at a time, and why): the same episodes either way."""


def outcome(summary: dict) -> dict:
    """`summary` without its timing fields and how it was stepped: what two runs of one seed must
    agree on."""
    return {key: value for key, value in summary.items() if key not in TIMING_FIELDS + STEPPING_FIELDS}


def summarize(results: list[EpisodeResult], **identity: object) -> dict:
    """Aggregate episodes (order-independent), as each field of `EpisodeResult` declares: rates,
    accuracy, means, worst cases; `identity` is copied in first, then the number of episodes.
    The controller's compute time per tick [ms] is the median of the episodes' medians
    (`solve_ms_p50`) and the worst episode's 95th percentile (`solve_ms_p95`): measured, so the
    only fields that differ between two runs of one seed (see `TIMING_FIELDS`)."""
    record = type(results[0]) if results else EpisodeResult
    return {**identity, "episodes": len(results), **summary_entries(record, results)}
