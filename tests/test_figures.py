"""Every figure a results folder gets is one a person would read: a title, every panel labelled,
never a blank picture. Each command runs on a tiny budget; every `savefig` is inspected as it
happens and every PNG written is opened afterwards."""

import matplotlib.pyplot as plt
import numpy as np
import pytest
import yaml
from matplotlib.figure import Figure
from typer.testing import CliRunner

from stack.apps.cli import app
from stack.deepcars.reproduce import reproduce
from tests.test_cli import tiny_config_file
from tests.test_deepcars import TINY as TINY_DEEPCARS
from tests.test_train import TINY as TINY_TRAINING


@pytest.fixture
def inspected_figures(monkeypatch):
    """Every figure saved: its title and each panel's labels, checked when `savefig` is called."""
    saved = []
    real_savefig = Figure.savefig

    def savefig(figure, path, *arguments, **keywords):
        panels = [axis for axis in figure.axes if axis.has_data()]
        title = figure.get_suptitle() or next((axis.get_title() for axis in panels if axis.get_title()), "")
        assert title, f"{path}: no title"
        for axis in panels:
            assert axis.get_ylabel() or axis.get_title(), f"{path}: a panel without a label or title"
        assert any(axis.get_xlabel() or axis.get_xticklabels() for axis in panels), f"{path}: no x axis"
        saved.append(str(path))
        return real_savefig(figure, path, *arguments, **keywords)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


def assert_not_blank(folder) -> list[str]:
    names = []
    for path in sorted(folder.rglob("*.png")):
        pixels = plt.imread(path)
        colours = np.unique(pixels.reshape(-1, pixels.shape[-1]), axis=0)
        assert len(colours) > 10, f"{path.name} is (nearly) one colour"
        names.append(path.name)
    return names


@pytest.mark.slow
def test_every_results_figure_has_a_title_labels_and_content(tmp_path, inspected_figures):
    config = str(tiny_config_file(tmp_path))
    runner = CliRunner()
    commands = [
        ["run", "-c", config, "--episodes", "2", "--out", str(tmp_path / "run")],
        [
            "compare",
            "-c",
            config,
            "--agents",
            "rule,keep-lane",
            "--episodes",
            "2",
            "--out",
            str(tmp_path / "cmp"),
        ],
        [
            "track",
            "--controller",
            "pid",
            "--plant",
            "kinematic",
            "--speeds",
            "20",
            "--out",
            str(tmp_path / "trk"),
        ],
    ]
    for command in commands:
        result = runner.invoke(app, [*command, "--no-progress"])
        assert result.exit_code == 0, result.output
    (training := tmp_path / "train.yaml").write_text(yaml.safe_dump(TINY_TRAINING))
    result = runner.invoke(
        app, ["train", "-c", str(training), "--out", str(tmp_path / "trn"), "--no-progress"]
    )
    assert result.exit_code == 0, result.output
    reproduce(tmp_path / "deepcars", budget=TINY_DEEPCARS, networks=("16",))
    written = assert_not_blank(tmp_path)
    expected = {"traces.png", "grid.png", "comparison.png", "training_curve.png", "training_curves.png"}
    assert expected <= set(written) and any(name.startswith("tracking_") for name in written)
    assert len(inspected_figures) >= len(written)
