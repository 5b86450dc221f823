"""A config that validates runs (issue 36): each section with every number at the low or the high
end of its range drives a short episode without an error."""

import typing

import annotated_types
import pytest
from pydantic import BaseModel

from controllers.config import ControllerConfig
from planner.safety import SafetyConfig
from stack.runs.episodes import run
from stack.settings.layers import OracleConfig, PerceptionConfig
from stack.settings.run import build_config
from tests.test_hostile_limits import numeric_fields

SECTIONS: dict[str, type[BaseModel]] = {
    "perception": PerceptionConfig,
    "planner.safety": SafetyConfig,
    "planner.oracle": OracleConfig,
    "controller": ControllerConfig,
}
TINIEST = 1e-300
"""Stands for a number just above a bound `gt=0`."""


def at_end(field: typing.Any, end: str, integer: bool) -> float | None:
    """The number at the `low` or `high` end of `field`'s range (just inside an open end)."""
    step = 1 if integer else None
    for bound in field.metadata:
        if end == "low" and isinstance(bound, annotated_types.Ge):
            return bound.ge
        if end == "low" and isinstance(bound, annotated_types.Gt):
            return bound.gt + (step or (TINIEST if bound.gt == 0 else bound.gt * 1e-9))
        if end == "high" and isinstance(bound, annotated_types.Le):
            return bound.le
        if end == "high" and isinstance(bound, annotated_types.Lt):
            return bound.lt - (step or bound.lt * 1e-9)
    return None


def section_at(section: str, end: str) -> dict[str, typing.Any]:
    """`section`'s data with every number at the `end` of its range (nested as the config is)."""
    data: dict[str, typing.Any] = {}
    for key, field in numeric_fields(SECTIONS[section]):
        kinds = typing.get_args(field.annotation) or (field.annotation,)
        if (value := at_end(field, end, int in kinds)) is not None:
            node = data
            *parents, leaf = key.split(".")
            for parent in parents:
                node = node.setdefault(parent, {})
            node[leaf] = value
    return data


def extreme_run(section: str, end: str, **changes: typing.Any) -> dict:
    values = section_at(section, end) | changes
    data: dict[str, typing.Any] = {
        "episodes": 1,
        "highway": {"vehicles_count": 10, "duration": 6},
        "planner": {"agent": "oracle" if section == "planner.oracle" else "rule"},
    }
    *parents, leaf = section.split(".")
    node = data
    for parent in parents:
        node = node.setdefault(parent, {})
    node[leaf] = node.get(leaf, {}) | values
    return run(build_config(data, f"{section} at its {end} ends"), progress=False).summary


@pytest.mark.parametrize("end", ["low", "high"])
@pytest.mark.parametrize("section", ["perception", "planner.safety"])
def test_a_section_at_the_ends_of_its_ranges_runs(section, end):
    assert extreme_run(section, end)["episodes"] == 1


@pytest.mark.parametrize("end", ["low", "high"])
def test_the_oracle_at_the_ends_of_its_ranges_runs(end):
    assert extreme_run("planner.oracle", end, depth=1, horizon_s=3.0)["episodes"] == 1


@pytest.mark.parametrize(
    ("controller", "end"),
    [
        *((name, end) for name in ("pid", "pure-pursuit", "stanley") for end in ("low", "high")),
        ("lqr", "high"),
        ("mpc", "low"),
        pytest.param("lqr", "low", marks=pytest.mark.slow),
        pytest.param("mpc", "high", marks=pytest.mark.slow),
    ],
)
def test_every_controller_at_the_ends_of_its_ranges_runs(controller, end):
    """(Slow: the LQR's gain schedule every 0.1 m/s takes seconds, the MPC's 200-step horizon
    minutes to build.)"""
    changes = {"type": controller}
    if end == "low":
        changes["emergency_decel_mps2"] = section_at("controller", "high")["comfort_decel_mps2"]
    assert extreme_run("controller", end, **changes)["episodes"] == 1
