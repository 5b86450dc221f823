"""`train.members`: one `drivestack train` makes an ensemble, its runs trained one after the other
in the folder's `seed-S` folders (each the run `--seed S` would make alone), then one model file
deciding on the mean of their Q-values; `--resume` keeps the members that finished."""

import json

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from planner.learned import load_agent
from planner.model_file import load_model
from stack.apps.cli import app
from tests.test_train import TINY

ENSEMBLE = {**TINY, "seed": 5, "train": {**TINY["train"], "members": 2}}


def train(*arguments: str) -> tuple[int, str]:
    result = CliRunner().invoke(app, ["train", "--no-progress", *arguments])
    return result.exit_code, result.output


@pytest.fixture(scope="module")
def ensemble(tmp_path_factory):
    """The tiny config with two members (seeds 5 and 6) trained in one command, and its folder."""
    folder = tmp_path_factory.mktemp("members")
    (config := folder / "ensemble.yaml").write_text(yaml.safe_dump(ENSEMBLE))
    code, output = train("--config", str(config), "--out", str(folder / "out"))
    assert code == 0, output
    return config, folder / "out"


def test_one_command_trains_each_seed_in_its_folder_then_writes_their_ensemble(ensemble, tmp_path):
    _, out = ensemble
    for seed in (5, 6):
        member = yaml.safe_load((out / f"seed-{seed}" / "config.yaml").read_text())
        assert member["seed"] == seed and member["train"]["members"] == 1
    assert yaml.safe_load((out / "config.yaml").read_text())["train"]["members"] == 2
    for kind in ("best.npz", "final.npz"):
        agent = load_agent(out / kind)
        assert agent.metadata.members == 2 and agent.metadata.member_seeds == (5, 6)
        batch = np.random.default_rng(1).uniform(-1, 1, (16, agent.metadata.observation_size))
        members = [load_agent(out / f"seed-{seed}" / kind).q_values(batch) for seed in (5, 6)]
        assert not np.allclose(*members), "two seeds, two networks"
        np.testing.assert_allclose(agent.q_values(batch), np.mean(members, axis=0), rtol=1e-5, atol=1e-6)
    summary = json.loads((out / "summary.json").read_text())
    assert [member["seed"] for member in summary["members"]] == [5, 6]
    assert all(member["steps"] == 40 and member["best_validation"] for member in summary["members"])
    assert summary["best_model"].endswith("best.npz") and summary["final_model"].endswith("final.npz")

    single = tmp_path / "single.yaml"
    single.write_text(yaml.safe_dump({**TINY, "seed": 6}))
    assert train("--config", str(single), "--out", str(tmp_path / "alone"))[0] == 0
    alone, member = (load_model(path / "final.npz")[0] for path in (tmp_path / "alone", out / "seed-6"))
    assert alone.keys() == member.keys()
    for name, weights in alone.items():
        np.testing.assert_array_equal(member[name], weights, err_msg=f"seed 6 alone is member 2: {name}")


def test_resume_trains_only_the_missing_members_and_refuses_a_finished_ensemble(ensemble, tmp_path):
    _, out = ensemble
    code, output = train("--resume", str(out))
    assert code == 2 and output.count("\n") == 1 and "finished its 2 members' 40 steps" in output, output

    copy = tmp_path / "copy"
    (copy / "seed-5").mkdir(parents=True)
    for path in (out / "seed-5").iterdir():
        if path.is_file():
            (copy / "seed-5" / path.name).write_bytes(path.read_bytes())
    for name in ("config.yaml", ".drivestack-owner.json"):
        if (out / name).is_file():
            (copy / name).write_bytes((out / name).read_bytes())
    kept = (copy / "seed-5" / "final.npz").stat().st_mtime_ns
    code, output = train("--resume", str(copy))
    assert code == 0, output
    assert "member 1 of 2 (seed 5): finished" in output
    assert (copy / "seed-5" / "final.npz").stat().st_mtime_ns == kept, "a finished member is kept"
    ours, theirs = load_model(copy / "final.npz"), load_model(out / "final.npz")
    assert ours[1] == theirs[1]
    for name, weights in theirs[0].items():
        np.testing.assert_array_equal(ours[0][name], weights, err_msg=name)


def test_an_ensemble_of_q_tables_or_in_a_sweep_is_refused_in_one_line(tmp_path):
    tables = {**TINY, "train": {**TINY["train"], "members": 2, "algorithm": "tabular", "encoding": "tabular"}}
    (config := tmp_path / "tables.yaml").write_text(yaml.safe_dump(tables))
    code, output = train("--config", str(config), "--out", str(tmp_path / "o"))
    assert code == 2 and output.count("\n") == 1 and "members: an ensemble is of Q-networks" in output, output
    assert not (tmp_path / "o").exists()

    (tmp_path / "base.yaml").write_text(yaml.safe_dump(ENSEMBLE))
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(yaml.safe_dump({"config": "base.yaml", "space": {"seed": [1, 2]}}))
    result = CliRunner().invoke(app, ["sweep", "--config", str(sweep), "--out", str(tmp_path / "s")])
    assert result.exit_code == 2 and "train.members: a trial trains one model" in result.output, result.output


TAUGHT = {
    **ENSEMBLE["train"],
    "worlds": 4,
    "envs": 1,
    "action_mask": True,
    "demonstrations": {"expert": "lookahead", "episodes": 3, "pretrain_steps": 5},
}
"""The tiny ensemble on batched worlds, taught by the lookahead first."""


def recordings(monkeypatch) -> list[int]:
    """The seeds of the runs that record demonstrations from now on, in order."""
    from stack.training import demonstrations

    recorded, collect = [], demonstrations.collect_demonstrations

    def counted(config, *args, **kwargs):
        recorded.append(config.seed)
        return collect(config, *args, **kwargs)

    monkeypatch.setattr(demonstrations, "collect_demonstrations", counted)
    return recorded


def test_members_record_their_demonstrations_once_and_are_the_runs_alone_in_turn_or_at_once(
    tmp_path, monkeypatch
):
    """The demonstrations are seeded from their own seed, not the run's: the ensemble records them
    for its first member and hands the same arrays to the next, which trains the model it trains
    alone (recording them itself), bit for bit. `train.member_jobs: 2` trains both members in
    processes of their own, the demonstrations recorded once here: every member file and the
    ensemble's byte for byte those of one after the other."""
    recorded = recordings(monkeypatch)
    for jobs in (1, 2):
        config = tmp_path / f"jobs-{jobs}.yaml"
        config.write_text(yaml.safe_dump({**ENSEMBLE, "train": {**TAUGHT, "member_jobs": jobs}}))
        code, output = train("--config", str(config), "--out", str(tmp_path / f"jobs-{jobs}"))
        assert code == 0, output
    assert recorded == [5, 5], "once for each ensemble, for its first member"
    (single := tmp_path / "single.yaml").write_text(
        yaml.safe_dump({**ENSEMBLE, "seed": 6, "train": {**TAUGHT, "members": 1}})
    )
    assert train("--config", str(single), "--out", str(tmp_path / "alone"))[0] == 0
    assert recorded == [5, 5, 6]
    for name in ("best.npz", "final.npz"):
        alone = (tmp_path / "alone" / name).read_bytes()
        assert (tmp_path / "jobs-1" / "seed-6" / name).read_bytes() == alone, name
    for name in ("seed-5/best.npz", "seed-5/final.npz", "seed-6/final.npz", "best.npz", "final.npz"):
        assert (tmp_path / "jobs-2" / name).read_bytes() == (tmp_path / "jobs-1" / name).read_bytes(), name


def test_members_at_once_must_fit_in_memory_together():
    from stack.settings.run import build_config
    from stack.training.checks import demonstrations_bytes, memory_refusal, replay_buffer_bytes

    data = {**ENSEMBLE, "train": {**ENSEMBLE["train"], "members": 3, "member_jobs": 3}}
    config = build_config(data)
    one = replay_buffer_bytes(config) + demonstrations_bytes(config)
    available = int(2 * one / 0.8)
    refusal = memory_refusal(config, available)
    assert refusal is not None and refusal.startswith("train.member_jobs: 3 members at once need")
    assert "\n" not in refusal
    two_at_once = build_config({**data, "train": {**data["train"], "member_jobs": 2}})
    assert memory_refusal(two_at_once, available) is None
