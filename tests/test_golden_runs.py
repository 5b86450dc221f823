"""Regression: short closed-loop runs, tick by tick, against stored results. Any change to the tick
(perception, safety, maneuver, controllers, metrics) that moves a number shows here. Regenerate with
`python -c "from tests.test_golden_runs import write_golden; write_golden()"` after an intended
change, and say why in the commit.

Numbers match to `TOLERANCE`, not bit for bit: numpy's vectorised kernels round differently on
different CPUs (AVX2 / AVX-512), which moves the last digit; a real change moves far more."""

import json
from pathlib import Path

import numpy as np
import pytest

from stack.results import episode_result
from stack.runs.episodes import run
from stack.settings.run import build_config

GOLDEN = Path(__file__).parent / "golden" / "runs.json"
ROAD = {"vehicles_count": 30, "duration": 12}
"""The cases' road: highway-v0's traffic, 30 vehicles, 12 s."""
CHANGES_ROAD = {**ROAD, "duration": 20}
"""The lane-change cases' road: from a drivable start the ego meets slower traffic after 12 s."""
CASES = {
    "ddqn-pid": {"seed": 1, "planner": {"agent": "ddqn"}},
    "mobil-mpc-changes": {
        "seed": 2,
        "planner": {"agent": "mobil"},
        "controller": {"type": "mpc"},
        "highway": CHANGES_ROAD,
    },
    "rule-pid-changes": {"seed": 2, "planner": {"agent": "rule"}, "highway": CHANGES_ROAD},
    "rule-pid-noisy": {
        "seed": 2,
        "planner": {"agent": "rule"},
        "perception": {
            "sensor": {"position_noise_m": 1.0, "false_positives": 1.0},
            "tracker": {"mode": "off"},
        },
    },
    "rule-pid-noisy-control-on-ground-truth": {
        "seed": 2,
        "planner": {"agent": "rule"},
        "perception": {
            "sensor": {"position_noise_m": 1.0, "false_positives": 1.0},
            "control_on_ground_truth": True,
        },
    },
}
"""The summary's `backend` is left out: every backend gives stock's trajectories, so the results
were written on `fast` and hold on `vector`. `rule-pid-noisy-control-on-ground-truth` keeps the
result of the noisy case from before safety and cruise acted on the perceived world (the agent
alone saw the noise then); `rule-pid-noisy` keeps its result from before the tracker (it acts on
each frame's raw detections: `perception.tracker.mode: off`)."""


TOLERANCE = {"rel": 1e-9, "abs": 1e-9}
"""How close a number must come to its stored value (relative, and absolute near zero)."""


def outcome(case: str) -> dict:
    data = {"episodes": 1, "highway": ROAD, **CASES[case]}
    results = run(build_config(data, case), progress=False)
    untimed = episode_result.outcome(results.summary)
    summary = {key: value for key, value in untimed.items() if key != "backend"}
    return {"summary": summary, "trace": results.episodes[0].trace}


@pytest.mark.parametrize("case", CASES)
def test_run_reproduces_its_golden_result(case):
    found, golden = outcome(case), json.loads(GOLDEN.read_text())[case]
    assert found["summary"].keys() == golden["summary"].keys()
    for key, value in golden["summary"].items():
        number = isinstance(value, float)
        assert found["summary"][key] == (pytest.approx(value, **TOLERANCE) if number else value), key
    assert found["trace"].keys() == golden["trace"].keys()
    for series, values in golden["trace"].items():
        assert len(found["trace"][series]) == len(values), series
        np.testing.assert_allclose(
            found["trace"][series], values, rtol=TOLERANCE["rel"], atol=TOLERANCE["abs"]
        )


def write_golden() -> None:
    GOLDEN.write_text(json.dumps({case: outcome(case) for case in CASES}, indent=1, sort_keys=True) + "\n")
