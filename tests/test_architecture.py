"""The import rules of docs/architecture.md, read from the source: the layers share only `records`,
`stack` imports downwards (apps -> core -> sim), no module grows past a sitting's reading."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("perception", "planner", "controllers")
PROJECT = (*LAYERS, "stack", "records")
MAX_LINES = 400
"""A module past this many lines holds more than one role (the median module is about 100)."""


def modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def project_imports(path: Path) -> set[str]:
    """Dotted names of the project modules `path` imports (at any depth, lazy imports included)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        found |= {name for name in names if name.split(".")[0] in PROJECT}
    return found


@pytest.mark.parametrize("layer", LAYERS)
def test_layers_import_only_themselves_and_the_records(layer):
    for path in modules(layer):
        foreign = {name for name in project_imports(path) if name.split(".")[0] not in (layer, "records")}
        assert not foreign, f"{path.relative_to(ROOT)} imports {sorted(foreign)}"


def test_records_import_only_records():
    for path in modules("records"):
        foreign = {name for name in project_imports(path) if name.split(".")[0] != "records"}
        assert not foreign, f"{path.relative_to(ROOT)} imports {sorted(foreign)}"


@pytest.mark.parametrize(
    ("part", "forbidden"),
    [("sim", ("stack.core", "stack.apps", "stack.deepcars")), ("core", ("stack.apps", "stack.deepcars"))],
)
def test_stack_imports_point_downwards(part, forbidden):
    for path in modules(f"stack/{part}"):
        upward = {name for name in project_imports(path) if name.startswith(forbidden)}
        assert not upward, f"{path.relative_to(ROOT)} imports {sorted(upward)}"


def test_no_module_is_longer_than_a_sitting():
    for package in PROJECT:
        for path in modules(package):
            lines = len(path.read_text().splitlines())
            assert lines <= MAX_LINES, f"{path.relative_to(ROOT)} has {lines} lines"


def test_every_registered_name_has_an_implementation():
    from controllers.config import ControllerConfig
    from controllers.tracker import make_controller
    from perception.grid import OccupancyGridBuilder
    from records import BACKENDS, CONTROLLER_NAMES, ENCODINGS, ROADS, GridConfig
    from stack.sim.highway import ENV_IDS
    from tests.helpers import scene

    assert tuple(ENV_IDS) == ROADS and all(tuple(ids) == BACKENDS for ids in ENV_IDS.values())
    for name in CONTROLLER_NAMES:
        assert callable(make_controller(ControllerConfig(type=name), 1 / 15).step)
    builder = OccupancyGridBuilder(GridConfig())
    grid = builder.build(scene(3, (0.0, 1), [(15.0, 4.0)]))
    for encoding in ENCODINGS:
        assert builder.space(encoding, 3).contains(
            grid.encode(encoding).astype(builder.space(encoding, 3).dtype)
        )
