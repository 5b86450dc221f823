"""`drivestack tracking`: how well the world the layers act on follows the simulator's truth, per
agent, over seeded episodes run one world at a time (`stack.results.tracking_quality`); a table on
the terminal and, in the results folder, the resolved config, `tracking.json` (the measures by
agent) and `summary.json` (those with the episodes, the first seed and the drivers)."""

from __future__ import annotations

from pathlib import Path

import typer

from records import child_seed
from stack.apps.resume import resolved_config
from stack.loop.closed_loop import ClosedLoop
from stack.results.tracking_quality import TrackingQuality, combined
from stack.runs.alone import run_agent_episode
from stack.runs.kept import kept_adapter, kept_agent
from stack.runtime.files import write_json, write_text
from stack.settings.run import RunConfig, drivers_of

COLUMNS = (
    ("precision", "precision", "{:.3f}"),
    ("recall", "recall", "{:.3f}"),
    ("position_rmse_m", "position RMSE m", "{:.2f}"),
    ("velocity_rmse_mps", "velocity RMSE m/s", "{:.2f}"),
    ("ospa_m", "OSPA m", "{:.2f}"),
    ("phantom_tracks_per_min", "phantom tracks / min", "{:.2f}"),
    ("identity_switches_per_min", "id switches / min", "{:.2f}"),
    ("emergency_brakings", "AEB / episode", "{:.2f}"),
)


def measure(config: RunConfig) -> dict[str, float]:
    """The tracking measures of `config.episodes` episodes of `config` from `config.seed`, with the
    episodes' emergency brakings a episode."""
    qualities, brakings, dt = [], 0, 0.0
    for episode in range(config.episodes):
        seed = child_seed(config.seed, episode)
        agent = kept_agent(config, seed)
        loop = ClosedLoop(config, kept_adapter(config), grid=agent.grid_config)
        quality = loop.quality = TrackingQuality()
        brakings += run_agent_episode(loop, agent, episode, seed).emergency_brakings
        qualities.append(quality)
        dt = loop.plant.dt
    measures = combined(qualities, dt)
    measures["emergency_brakings"] = brakings / max(config.episodes, 1)
    return measures


def report(configs: dict[str, RunConfig], folder: Path) -> bool:
    """Measure each agent's config, print one row each and write the resolved config,
    `tracking.json` and `summary.json` into `folder`; False (`until_interrupted`: nothing cut short)."""
    first = next(iter(configs.values()))
    folder.mkdir(parents=True, exist_ok=True)
    write_text(folder / "config.yaml", resolved_config(list(configs.values())))
    rows = {agent: measure(config) for agent, config in configs.items()}
    header = ["agent", *(label for _, label, _ in COLUMNS)]
    typer.echo(" | ".join(header))
    for agent, measures in rows.items():
        cells = [form.format(measures[key]) for key, _, form in COLUMNS]
        typer.echo(" | ".join([agent, *cells]))
    write_json(folder / "tracking.json", rows)
    summary = {"episodes": first.episodes, "seed": first.seed, "drivers": drivers_of(first.highway)}
    write_json(folder / "summary.json", {**summary, "agents": rows})
    typer.echo(f"wrote {folder / 'tracking.json'}")
    return False
