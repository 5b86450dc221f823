"""A metric is its field and its measurer (docs/architecture.md, "adding a metric"): a field declared
here, with its measurer and nothing else, is measured by the per-world loop and by the batch alike,
and reaches summary.json and episodes.csv."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from stack.apps.run import write_results
from stack.results.episode_fields import Summarized, declared, mean
from stack.results.episode_measures import EpisodeSamples
from stack.results.episode_result import EpisodeResult
from stack.runs.episodes import run
from stack.settings.run import build_config

BRISK_SPEED_MPS = 20.0


def time_brisk_s(samples: EpisodeSamples) -> float:
    """The ticks that ended with the ego above `BRISK_SPEED_MPS`, times the tick [s]."""
    return float(np.count_nonzero(samples.speed[1:] > BRISK_SPEED_MPS) * samples.dt)


@dataclass(frozen=True)
class WithBriskTime(EpisodeResult):
    """The episode record with one more metric, declared as every field of it is."""

    time_brisk_s: float = field(
        default=0.0,
        metadata=declared("s", "progress", summary=(Summarized("time_brisk_s", mean),), measure=time_brisk_s),
    )


@pytest.fixture
def declared_metric(monkeypatch: pytest.MonkeyPatch) -> None:
    """The record both paths build is the one with the metric."""
    monkeypatch.setattr("stack.loop.closed_loop.EpisodeResult", WithBriskTime)
    monkeypatch.setattr("stack.batch.closed_loop_batch.EpisodeResult", WithBriskTime)


def written(tmp_path: Path, batched: bool) -> tuple[dict, list[dict[str, str]], list[float]]:
    """summary.json, episodes.csv and the measured values of two episodes stepped one way."""
    config = build_config({}, "test", seed=1013000, episodes=2, planner__agent="mobil", sim__batched=batched)
    results = run(config, progress=False, snapshot=False)
    assert results.summary["stepping"] == ("batched" if batched else "per-world")
    out = tmp_path / ("batched" if batched else "per-world")
    write_results(out, results.summary, results.episodes)
    with (out / "episodes.csv").open() as file:
        rows = list(csv.DictReader(file))
    measured = [episode.time_brisk_s for episode in results.episodes if isinstance(episode, WithBriskTime)]
    return json.loads((out / "summary.json").read_text()), rows, measured


@pytest.mark.usefixtures("declared_metric")
def test_a_metric_declared_with_its_measurer_reaches_both_paths_and_the_files(tmp_path: Path) -> None:
    batched_summary, batched_rows, batched = written(tmp_path, batched=True)
    alone_summary, alone_rows, alone = written(tmp_path, batched=False)
    assert len(batched) == len(alone) == 2, "both paths build the record with the metric"
    assert batched == alone and sum(alone) > 0
    assert batched_summary["time_brisk_s"] == alone_summary["time_brisk_s"] == pytest.approx(np.mean(alone))
    assert [float(row["time_brisk_s"]) for row in batched_rows] == alone
    assert [float(row["time_brisk_s"]) for row in alone_rows] == alone
