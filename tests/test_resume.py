"""`run --resume` and `compare --resume` beyond the stop-and-resume of test_signals: the run beside
another agent, a fresh start over old journals, a finished folder, and what is refused."""

import json

from typer.testing import CliRunner

from stack.apps.cli import app
from stack.runs import episodes
from stack.runs.episodes import run_episode
from stack.runtime.owner import MARKER
from stack.settings.run import load_config
from tests.test_cli import tiny_config_file
from tests.test_signals import untimed


def test_a_run_beside_another_agent_resumes_each_agent_from_its_own_journal(tmp_path, monkeypatch):
    config = tiny_config_file(tmp_path)
    arguments = ["run", "-c", str(config), "--agent", "rule", "--beside", "keep-lane", "--episodes", "3"]
    whole = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "whole"), "--no-progress"])
    assert whole.exit_code == 0, whole.output
    out = tmp_path / "out"
    started = CliRunner().invoke(app, [*arguments, "--episodes", "1", "--out", str(out), "--no-progress"])
    assert started.exit_code == 0, started.output
    refused = CliRunner().invoke(app, [*arguments, "--episodes", "1", "--out", str(out), "--resume"])
    assert refused.exit_code == 2 and "nothing to resume" in refused.output

    for name in ("config.yaml", MARKER):
        (out / name).write_text((tmp_path / "whole" / name).read_text())
    beside = load_config(config, planner__agent="keep-lane", episodes=3)
    (out / "keep-lane.episodes.partial.jsonl").write_text(json.dumps(run_episode(beside, 1).row()) + "\n")
    ran: list[tuple[str, int]] = []
    alone, batched = episodes.run_episode, episodes.run_batched
    monkeypatch.setattr(
        episodes,
        "run_episode",
        lambda c, e, *more, **kw: ran.append((c.planner.agent, e)) or alone(c, e, *more, **kw),
    )
    monkeypatch.setattr(
        episodes,
        "run_batched",
        lambda c, es, **kw: ran.extend((c.planner.agent, e) for e in es) or batched(c, es, **kw),
    )
    resumed = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    assert resumed.exit_code == 0, resumed.output
    assert ran == [("rule", 0), ("rule", 1), ("rule", 2), ("keep-lane", 0), ("keep-lane", 2)]
    assert untimed(out / "beside.json") == untimed(tmp_path / "whole" / "beside.json")
    assert not list(out.glob("*.partial.jsonl"))


def test_a_fresh_start_empties_the_journals_an_interrupted_run_left(tmp_path):
    out = tmp_path / "out"
    arguments = ["compare", "-c", str(tiny_config_file(tmp_path)), "--agents", "keep-lane", "--episodes", "1"]
    first = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert first.exit_code == 0, first.output
    stale = out / "keep-lane.episodes.partial.jsonl"
    stale.write_text('{"episode": 0, "seed": 0, "stale": true}\n' * 50)
    result = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert result.exit_code == 0 and not stale.exists(), result.output


def test_the_same_agent_twice_is_refused_before_any_work(tmp_path):
    config = str(tiny_config_file(tmp_path))
    for arguments, message in (
        (["run", "-c", config, "--agent", "rule", "--beside", "rule"], "--beside: expected an agent other"),
        (["compare", "-c", config, "--agents", "rule,mobil,rule"], "--agents: expected each agent once"),
    ):
        result = CliRunner().invoke(app, [*arguments, "--out", str(tmp_path / "out")])
        assert result.exit_code == 2 and message in result.output, result.output
    assert not (tmp_path / "out").exists()


def test_a_journal_an_earlier_version_wrote_is_refused_in_one_line(tmp_path):
    config = tiny_config_file(tmp_path)
    arguments = ["run", "-c", str(config), "--agent", "keep-lane", "--episodes", "2"]
    out = tmp_path / "out"
    started = CliRunner().invoke(app, [*arguments, "--out", str(out), "--no-progress"])
    assert started.exit_code == 0, started.output
    older = run_episode(load_config(config, planner__agent="keep-lane", episodes=2), 0).row()
    older.pop("time_in_leftmost_lane_s")
    (out / "keep-lane.episodes.partial.jsonl").write_text(json.dumps(older) + "\n")
    refused = CliRunner().invoke(app, [*arguments, "--out", str(out), "--resume", "--no-progress"])
    lines = refused.output.strip().splitlines()
    assert refused.exit_code == 2 and len(lines) == 1, refused.output
    assert "written by an earlier drivestack (its episodes lack time_in_leftmost_lane_s)" in lines[0]
