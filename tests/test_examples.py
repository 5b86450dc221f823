"""The examples run as a user would run them, from outside the checkout."""

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.py"))


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda path: path.name)
def test_example_runs(example, tmp_path):
    result = subprocess.run(
        [sys.executable, str(example)], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert "mean speed" in result.stdout


def test_the_public_api_is_exported():
    import controllers
    import perception
    import planner
    import stack
    from stack.runs.episodes import run_episode
    from stack.settings.run import load_config
    from stack.sim.highway import world_state

    assert {"OccupancyGridBuilder", "GridConfig", "WorldState"} <= set(perception.__all__)
    assert {"make_agent", "load_agent", "decide"} <= set(planner.__all__)
    assert {"make_controller", "ControllerConfig"} <= set(controllers.__all__)
    exported = (stack.run_episode, stack.world_state, stack.load_config)
    assert exported == (run_episode, world_state, load_config)
    for package in (controllers, perception, planner, stack):
        for name in package.__all__:
            assert getattr(package, name).__name__ == name, f"{package.__name__}.{name}"
    with pytest.raises(AttributeError):
        stack.nothing_here  # noqa: B018
