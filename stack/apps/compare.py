"""`drivestack compare`: several agents on the same seeded episodes; every metric with its 95 %
confidence interval and, with a baseline, the paired difference to it (`stack.runs.statistics`).
Writes comparison.json, comparison.png and episodes.csv (every agent's episodes, for pairings the
table does not show) and prints one markdown table. The figure and the tables show a plug-in by its
class name (`common.plugins.short_labels`); the files name it in full."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
from matplotlib.axes import Axes

from common.plugins import short_labels
from stack.apps.resume import started
from stack.apps.view import view_command_line
from stack.loop.recording import RECORDINGS, agent_folders
from stack.results.episode_fields import columns, interval_text
from stack.results.episode_fields import intervals as declared_intervals
from stack.results.episode_result import EpisodeResult
from stack.runs.episodes import RunResults, run
from stack.runs.statistics import Interval, mean_interval, paired_difference, rate_interval
from stack.runtime.executors import shared_workers
from stack.runtime.files import EpisodeJournal, save_figure, write_csv, write_json
from stack.runtime.interrupts import deferred
from stack.settings.run import RunConfig
from stack.worlds.drivers import HIGHWAY_ENV

PANELS = (
    ("collision_rate", "collision rate [%]", 100.0),
    ("mean_speed", "mean speed [m/s]", 1.0),
    ("lane_changes", "lane changes / episode", 1.0),
)


def intervals(results: RunResults) -> dict[str, Interval]:
    """Every reported metric of one agent with its 95 % interval: each field of `EpisodeResult`
    that declares one, as a rate of its episodes or a mean over them (none can be negative)."""
    episodes = results.episodes
    found = {}
    for name, interval in declared_intervals(EpisodeResult):
        values = [getattr(e, name) for e in episodes]
        if interval.kind == "rate":
            found[interval.key] = rate_interval(sum(values), len(episodes))
        else:
            found[interval.key] = mean_interval(values, floor=0.0)
    return found


def differences(results: RunResults, baseline: RunResults) -> dict[str, Interval]:
    """Agent minus baseline, episode by episode (same seeds), for every reported metric, over the
    episodes both finished (all of them unless the comparison was interrupted)."""
    theirs = {e.episode: e for e in baseline.episodes}
    shared = [(e, theirs[e.episode]) for e in results.episodes if e.episode in theirs]
    return {
        interval.key: paired_difference(
            [float(getattr(mine, name)) for mine, _ in shared],
            [float(getattr(other, name)) for _, other in shared],
        )
        for name, interval in declared_intervals(EpisodeResult)
    }


def compare(
    configs: list[RunConfig],
    journals: list[EpisodeJournal],
    jobs: int = 1,
    progress: bool = True,
    ray: str | None = None,
    done: dict[str, list[EpisodeResult]] | None = None,
    record: Path | None = None,
) -> list[RunResults]:
    """One run per config (one config per agent, the same episodes and seeds), over `jobs`
    processes (started once for all the agents) or as Ray tasks at address `ray`, each finished
    episode recorded in its agent's journal as it finishes; `done` holds each agent's episodes an
    interrupted comparison finished (`stack.apps.resume.resumable`). Ctrl-C stops the comparison:
    the agents run so far are returned (the last one with the episodes it finished); none raises
    KeyboardInterrupt. With `record` (a folder), each agent's episodes are recorded into its own
    subfolder (`stack.loop.recording.agent_folders`)."""
    runs: list[RunResults] = []
    folders = agent_folders([config.planner.agent for config in configs])
    with shared_workers():
        for config, journal in zip(configs, journals, strict=True):
            finished = (done or {}).get(config.planner.agent, [])
            try:
                runs.append(
                    run(
                        config,
                        progress=progress,
                        jobs=jobs,
                        ray=ray,
                        on_finished=journal.record,
                        done=finished,
                        record=record / folders[config.planner.agent] if record is not None else None,
                        snapshot=False,
                    )
                )
            except KeyboardInterrupt:
                if not runs:
                    raise
                break
            if runs[-1].summary["interrupted"]:
                break
    return runs


def comparison(runs: list[RunResults], baseline: str | None = None) -> list[dict[str, Any]]:
    """Per agent: its summary, `intervals` {metric: [value, low, high]} and, with a baseline,
    `baseline` and `difference` {metric: [agent - baseline, low, high]}."""
    reference = next((r for r in runs if r.summary["agent"] == baseline), None)
    rows = []
    for results in runs:
        row = {**results.summary, "intervals": {k: v.as_list() for k, v in intervals(results).items()}}
        if reference is not None:
            row["baseline"] = baseline
            row["difference"] = {k: v.as_list() for k, v in differences(results, reference).items()}
        rows.append(row)
    return rows


def compare_and_report(
    configs: list[RunConfig],
    out: Path,
    jobs: int,
    progress: bool,
    baseline: str | None = None,
    ray: str | None = None,
    done: dict[str, list[EpisodeResult]] | None = None,
    record: bool = False,
) -> bool:
    """Run every config, write `out` (comparison.json, comparison.png), print the table; True
    when Ctrl-C cut the comparison short (the agents run so far are written, the journals kept
    for `--resume`). `done`: the episodes resumed (`stack.apps.resume.resumable`). With `record`,
    the episodes' recordings go to out/recordings/AGENT, and the command that opens each agent's
    worst episode is printed."""
    journals = started(configs, out, done)
    folder = out / RECORDINGS if record else None
    runs = compare(configs, journals, jobs=jobs, progress=progress, ray=ray, done=done, record=folder)
    interrupted = len(runs) < len(configs) or bool(runs[-1].summary["interrupted"])
    rows = comparison(runs, baseline)
    with deferred(interrupt_after=False):
        write_comparison(rows, out)
        for name, row in (
            ("episodes.csv", EpisodeResult.outcome_row),
            ("timings.csv", EpisodeResult.timing_row),
        ):
            write_csv(out / name, [{"agent": r.summary["agent"], **row(e)} for r in runs for e in r.episodes])
        for journal in journals if not interrupted else []:
            journal.discard()
    print(markdown(rows), end="")
    stopped = " (interrupted: the agents run so far; the same command with --resume finishes it)"
    print(f"results: {out}" + (stopped if interrupted else ""))
    if folder is not None:
        folders = agent_folders([config.planner.agent for config in configs])
        for results in runs:
            name = folders[results.summary["agent"]]
            if any((folder / name).glob("episode-*.rrd")):
                print(f"worst episode of {name}: {view_command_line(out, '--worst', '--agent', name)}")
    return interrupted


def write_comparison(rows: list[dict[str, Any]], out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "comparison.json", rows)
    with_difference = "difference" in rows[0]
    panels = len(PANELS) + with_difference
    figure, axes = plt.subplots(1, panels, figsize=(4.2 * panels, 4.2))
    names = shown(rows)
    for axis, (metric, label, scale) in zip(axes, PANELS, strict=False):
        _bars(axis, names, [[scale * v for v in row["intervals"][metric]] for row in rows], label)
    if with_difference:
        values = [row["difference"]["mean_speed"] for row in rows]
        _bars(axes[-1], names, values, f"mean speed - {shown_baseline(rows)} [m/s], paired")
        axes[-1].axhline(0.0, color="black", lw=0.8)
    first = rows[0]
    figure.suptitle(
        f"{first['scenario'] or 'config'}{drivers_label(first)}: {first['episodes']} seeded episodes "
        f"from seed {first['seed']}, "
        f"controller {short_labels([first['controller']])[0]} (bars: 95 % confidence intervals)"
    )
    figure.tight_layout()
    save_figure(figure, out / "comparison.png", dpi=100)
    plt.close(figure)


def drivers_label(row: dict[str, Any]) -> str:
    """ ", DRIVERS drivers" for a run whose traffic has a driver population other than highway-env's."""
    drivers = row.get("drivers")
    if drivers is None:
        return ""
    named = drivers if isinstance(drivers, str) else ", ".join(f"{k} {v:g}" for k, v in drivers.items())
    return f", {named} drivers"


def shown(rows: list[dict[str, Any]]) -> list[str]:
    """The agents of `rows` as the figure and the tables name them (`short_labels`)."""
    return short_labels([row["agent"] for row in rows])


def shown_baseline(rows: list[dict[str, Any]]) -> str:
    """The baseline of `rows` (one of their agents) as the figure and the tables name it."""
    return dict(zip((row["agent"] for row in rows), shown(rows), strict=True))[rows[0]["baseline"]]


def _bars(axis: Axes, names: list[str], intervals: list[list[float]], label: str) -> None:
    """Bars at the values with their intervals as error bars and the values written on them."""
    values = [value for value, _, _ in intervals]
    errors = [[value - low for value, low, _ in intervals], [high - value for value, _, high in intervals]]
    bars = axis.bar(names, values, yerr=errors, capsize=4, color="tab:blue", alpha=0.8)
    low, high = min(lo for _, lo, _ in intervals), max(hi for _, _, hi in intervals)
    if high - low < 1e-9:
        axis.set_ylim(low - 1.0, high + 1.0)
    span = max(abs(high), abs(low), 1e-9)
    for bar, value in zip(bars, values, strict=True):
        inside = abs(value) > 0.2 * span
        axis.annotate(
            f"{value:.2f}",
            (bar.get_x() + bar.get_width() / 2, value / 2 if inside else value),
            xytext=(0, 0 if inside else 3),
            textcoords="offset points",
            ha="center",
            va="center" if inside else "bottom",
            color="white" if inside else "black",
        )
    axis.set_title(label, fontsize="medium")
    axis.tick_params(axis="x", rotation=30)
    axis.grid(axis="y", alpha=0.3)


def markdown(rows: list[dict[str, Any]]) -> str:
    """The table, below the line naming the traffic's drivers (`population_line`): every metric as
    value [95 % interval]; paired differences with a baseline."""
    shown_columns = columns(EpisodeResult, "agents")
    header = "| agent | episodes | " + " | ".join(column.header for column in shown_columns) + " |"
    baseline = shown_baseline(rows) if rows[0].get("baseline") else None
    if baseline:
        header += f" speed - {baseline} m/s | collision rate - {baseline} % |"
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for row, name in zip(rows, shown(rows), strict=True):
        line = f"| {name} | {row['episodes']} | " + " | ".join(c.cell(row) for c in shown_columns) + " |"
        if baseline:
            difference = row["difference"]
            line += f" {interval_text(difference['mean_speed'], sign='+')} |"
            line += f" {interval_text(difference['collision_rate'], 100, 1, '+')} |"
        lines.append(line)
    return population_line(rows[0]) + "\n".join(lines) + "\n\n" + safety_markdown(rows)


def population_line(row: dict[str, Any]) -> str:
    """ "traffic drivers: POPULATION" and a blank line, for a run's summary row (`drivers`, absent
    for highway-env's own)."""
    drivers = row.get("drivers", HIGHWAY_ENV)
    named = drivers if isinstance(drivers, str) else ", ".join(f"{k} {v:g}" for k, v in drivers.items())
    return f"traffic drivers: {named}\n\n"


def safety_markdown(rows: list[dict[str, Any]]) -> str:
    """The safety table (docs/envelope.md): the safety columns `EpisodeResult` declares (at-fault
    collisions and road departures as rates with their intervals, the worst minimum TTC, time
    below R157's minimum following distance, emergency brakings, the longest standstill ...)."""
    shown_columns = columns(EpisodeResult, "safety")
    header = "| agent | " + " | ".join(column.header for column in shown_columns) + " |"
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for row, name in zip(rows, shown(rows), strict=True):
        lines.append(f"| {name} | " + " | ".join(column.cell(row) for column in shown_columns) + " |")
    return "\n".join(lines) + "\n"
