"""`drivestack run`: seeded closed-loop episodes, and their results folder (summary.json,
episodes.csv, a speed / lateral-position plot, the grid over the road, optional video)."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import matplotlib.pyplot as plt
import numpy as np
from rich.console import Console
from rich.table import Table

from common.plugins import short_labels
from perception.plot import plot_grid_over_road
from stack.apps.compare import comparison, markdown
from stack.apps.resume import started
from stack.apps.view import view_command_line
from stack.loop.closed_loop import VIDEO_FRAME_TICKS
from stack.loop.recording import RECORDINGS
from stack.results.episode_fields import columns, summary_rows
from stack.results.episode_result import EpisodeResult
from stack.runs.episodes import run
from stack.runtime.files import replacing, write_csv, write_json
from stack.runtime.interrupts import deferred
from stack.settings.run import RunConfig

LANE_CHANGE_SPEED = 0.3
"""Lateral speed [m/s] above which an episode counts as changing lane in the traces plot."""
CONTROL_RATE_HZ = 15
"""Control ticks per second the GIF's timing assumes (highway-env's default 15 Hz): it plays in
real time."""


def run_and_report(
    configs: list[RunConfig],
    out: Path,
    video: bool,
    jobs: int,
    progress: bool,
    ray: str | None = None,
    done: dict[str, list[EpisodeResult]] | None = None,
    record: bool = False,
) -> bool:
    """Run the first config's episodes (over `jobs` processes, or Ray tasks at address `ray`),
    write `out`, print the tables; True when Ctrl-C cut the run short (the finished episodes are
    written, and kept journaled for `--resume`). Raises KeyboardInterrupt if none finished. A
    second config (`--beside AGENT`) then drives the same seeds: `beside.json` and a table hold
    both agents with the paired difference to it. `done`: the episodes resumed
    (`stack.apps.resume.resumable`). With `record`, every episode run writes its rerun recording
    into out/recordings (the `--beside` agent's into out/recordings/beside)."""
    journals = started(configs, out, done)
    finished = [(done or {}).get(config.planner.agent, []) for config in configs]
    folder = out / RECORDINGS if record else None
    results = run(
        configs[0],
        video,
        progress,
        jobs,
        ray,
        on_finished=journals[0].record,
        done=finished[0],
        record=folder,
    )
    with deferred(interrupt_after=False):
        write_results(out, results.summary, results.episodes, results.frames)
    print_tables(results.summary, results.episodes)
    for note in undrawn(out, results.episodes):
        Console().print(note, highlight=False)
    interrupted = bool(results.summary["interrupted"])
    rows = None
    if len(configs) > 1 and not interrupted:
        try:
            beside_folder = folder / "beside" if folder is not None else None
            beside = run(
                configs[1],
                False,
                progress,
                jobs,
                ray,
                journals[1].record,
                finished[1],
                beside_folder,
                snapshot=False,
            )
            interrupted = bool(beside.summary["interrupted"])
            rows = comparison([results, beside], baseline=configs[1].planner.agent)
        except KeyboardInterrupt:
            interrupted = True
    with deferred(interrupt_after=False):
        if rows is not None:
            write_json(out / "beside.json", rows)
        for journal in journals if not interrupted else []:
            journal.discard()
    if rows is not None:
        print(markdown(rows), end="")
    stopped = " (interrupted: the same command with --resume finishes it)"
    Console().print(f"results: {out}" + (stopped if interrupted else ""))
    if folder is not None and any(folder.glob("episode-*.rrd")):
        Console().print(
            f"replay the worst episode: {view_command_line(out, '--worst')}",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
    return interrupted


def write_results(
    out: Path, summary: dict, episodes: list[EpisodeResult], frames: list[np.ndarray] | None = None
) -> None:
    """The results folder, each file written whole (`stack.runtime.files`)."""
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "summary.json", summary)
    write_csv(out / "episodes.csv", [episode.outcome_row() for episode in episodes])
    write_csv(out / "timings.csv", [episode.timing_row() for episode in episodes])
    if any(episode.trace for episode in episodes):
        with replacing(out / "traces.png") as path:
            plot_traces(episodes, path, summary)
    if episodes[0].snapshot is not None:
        with replacing(out / "grid.png") as path:
            plot_grid_over_road(*episodes[0].snapshot, path)
    if frames:
        duration_ms = 1000 * VIDEO_FRAME_TICKS / CONTROL_RATE_HZ
        with replacing(out / "episode0.gif") as path:
            # imageio's stub types the frames as list[ArrayLike], invariant: list[np.ndarray] is refused
            imageio.mimsave(path, frames, duration=duration_ms, loop=0)  # type: ignore[arg-type]


def undrawn(out: Path, episodes: list[EpisodeResult]) -> list[str]:
    """What a resumed run could not draw, one line each: episodes resumed from the journal keep
    no traces (traces.png) and no snapshot of the road (grid.png, from episode 0)."""
    notes = []
    for name, missing, why in (
        ("traces.png", not any(e.trace for e in episodes), "every episode was resumed from the journal"),
        ("grid.png", episodes[0].snapshot is None, "episode 0 was resumed from the journal"),
    ):
        if missing:
            kept = "kept from before --resume" if (out / name).is_file() else "not drawn"
            notes.append(f"{name}: {kept} ({why}, which keeps no traces or road snapshots)")
    return notes


FEW_EPISODES = 8
"""Up to this many episodes, traces are drawn one line each; beyond, as median and band."""


def plot_traces(episodes: list[EpisodeResult], path: Path, summary: dict) -> None:
    """Ego speed and lateral motion over time: one line per episode for a few episodes; for many,
    the median speed with its 10-90 % band and how many episodes are changing lane at each time.
    Episodes resumed from a journal have no traces: the plot holds those run in this process."""
    figure, (speed_axis, lateral_axis) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    first, last = episodes[0].seed, episodes[-1].seed
    traced = [episode for episode in episodes if episode.trace]
    resumed = f" ({len(traced)} traced: those run after --resume)" if len(traced) < len(episodes) else ""
    figure.suptitle(
        f"{agent_and_controller(summary)}, {summary.get('scenario') or 'configured world'}, "
        f"{summary.get('plant', 'kinematic')} plant: {len(episodes)} episodes, seeds {first}-{last}{resumed}"
    )
    if len(traced) <= FEW_EPISODES:
        for episode in traced:
            label = f"seed {episode.seed}" + (" (crash)" if episode.crashed else "")
            speed_axis.plot(episode.trace["time"], episode.trace["speed"], label=label)
            lateral_axis.plot(episode.trace["time"], episode.trace["d"])
        lateral_axis.set_ylabel("lateral position d [m]")
        lateral_axis.invert_yaxis()
        speed_axis.legend(loc="lower right", fontsize="small", ncol=4)
    else:
        longest = max(traced, key=lambda e: len(e.trace["time"]))
        time = np.asarray(longest.trace["time"])
        speed = np.full((len(traced), len(time)), np.nan)
        lateral_speed = np.full_like(speed, np.nan)
        for row, episode in enumerate(traced):
            ticks = len(episode.trace["time"])
            speed[row, :ticks] = episode.trace["speed"]
            lateral_speed[row, 1:ticks] = np.abs(np.diff(episode.trace["d"])) / np.diff(time[:ticks])
        low, median, high = np.nanpercentile(speed, [10, 50, 90], axis=0)
        speed_axis.fill_between(time, low, high, alpha=0.3, label="10-90 % of episodes")
        speed_axis.plot(time, median, label="median")
        speed_axis.legend(loc="lower right", fontsize="small")
        lateral_axis.plot(time, np.sum(lateral_speed > LANE_CHANGE_SPEED, axis=0))
        lateral_axis.set_ylabel("episodes changing lane")
    speed_axis.set_ylabel("speed [m/s]")
    lateral_axis.set_xlabel("time [s]")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def agent_and_controller(summary: dict) -> str:
    """`agent + controller` of a run's summary, a plug-in by its class name (`short_labels`)."""
    return " + ".join(short_labels([summary["agent"]]) + short_labels([summary["controller"]]))


def print_tables(summary: dict, episodes: list[EpisodeResult], console: Console | None = None) -> None:
    console = console or Console()
    table = Table(title="episodes")
    shown = columns(EpisodeResult, "episodes")
    for column in shown:
        table.add_column(column.header, justify="right")
    for episode in episodes:
        row = episode.row()
        table.add_row(*(column.cell(row) for column in shown))
    console.print(table)
    overview = Table(title=f"summary: {agent_and_controller(summary)}")
    overview.add_column("metric")
    overview.add_column("value", justify="right")
    overview.add_row("episodes", str(summary["episodes"]))
    for label, text in summary_rows(EpisodeResult, summary):
        overview.add_row(label, text)
    console.print(overview)
