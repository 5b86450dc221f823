"""The import rules of docs/architecture.md, read from the source: the layers share only `records` and
`common`, `records` holds data and names only, `stack` imports downwards (apps -> training ->
assessment -> runs -> agents -> batch -> loop -> results -> rrd -> sim -> settings -> runtime), no
import circle closes, no two classes share a name, no module grows past a sitting's reading, and no
folder of `stack` grows into a catch-all."""

import ast
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("perception", "planner", "controllers")
GROUND = ("records", "common")
"""The ground floor every layer may import: the shared records and names, and the shared behaviour."""
PROJECT = (*LAYERS, "stack", *GROUND)
MAX_LINES = 400
"""A module past this many lines holds more than one role (the median module is about 100)."""
MAX_FOLDER_LINES = 1_500
"""A folder of `stack` past this many lines holds more than one role (the loop, the largest, is ~1,200)."""
STACK_FLOORS = (
    "runtime",
    "worlds",
    "settings",
    "sim",
    "rrd",
    "results",
    "fault",
    "loop",
    "batch",
    "agents",
    "runs",
    "assessment",
    "training",
    "apps",
)
"""The folders of `stack`, lowest first: each imports only those before it (and itself); `deepcars`
stands alone on `runtime`, and only `apps` (its command) imports it."""


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


def module_name(path: Path) -> str:
    """The dotted name `path` is imported as (a package by its folder)."""
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """Each project module -> the project modules it imports, at module level, under TYPE_CHECKING
    and inside functions alike; `from a import b` counts `a.b` when that is a module, else `a`."""
    paths = {module_name(path): path for package in PROJECT for path in modules(package)}

    def module_of(name: str) -> str | None:
        while name not in paths and "." in name:
            name = name.rpartition(".")[0]
        return name if name in paths else None

    graph = {}
    for name, path in paths.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = []
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets += [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                    base = f"{anchor}.{base}".rstrip(".")
                targets += [f"{base}.{alias.name}" for alias in node.names]
        graph[name] = {found for target in targets if (found := module_of(target)) not in (None, name)}
    return graph


def first_circle(graph: dict[str, set[str]]) -> list[str] | None:
    """Modules that import each other round a circle (the first back to the start), or None."""
    done: set[str] = set()
    path: list[str] = []

    def visit(name: str) -> list[str] | None:
        path.append(name)
        for other in sorted(graph[name]):
            if other in path:
                return path[path.index(other) :] + [other]
            if other not in done and (circle := visit(other)):
                return circle
        done.add(path.pop())
        return None

    for name in sorted(graph):
        if name not in done and (circle := visit(name)):
            return circle
    return None


def test_the_import_graph_sees_every_kind_of_import():
    graph = import_graph()
    assert "controllers.protocol" in graph["controllers.mpc"]
    assert "stack.runtime.ray_tasks" in graph["stack.runtime.executors"]
    assert "stack.apps.track_record" in graph["stack.apps.track_report"]
    assert "perception.features" in graph["perception.grid"]
    assert first_circle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert first_circle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_no_import_circle():
    circle = first_circle(import_graph())
    assert circle is None, "import circle: " + " -> ".join(circle or [])


def test_no_two_classes_share_a_name():
    defined: dict[str, list[str]] = {}
    for package in PROJECT:
        for path in modules(package):
            for node in ast.parse(path.read_text()).body:
                if isinstance(node, ast.ClassDef):
                    defined.setdefault(node.name, []).append(module_name(path))
    shared = {name: where for name, where in defined.items() if len(where) > 1}
    assert not shared, f"classes of one name in several modules: {shared}"


@pytest.mark.parametrize("layer", LAYERS)
def test_layers_import_only_themselves_and_the_ground_floor(layer):
    for path in modules(layer):
        foreign = {name for name in project_imports(path) if name.split(".")[0] not in (layer, *GROUND)}
        assert not foreign, f"{path.relative_to(ROOT)} imports {sorted(foreign)}"


def test_records_import_only_records():
    for path in modules("records"):
        foreign = {name for name in project_imports(path) if name.split(".")[0] != "records"}
        assert not foreign, f"{path.relative_to(ROOT)} imports {sorted(foreign)}"


def test_common_imports_only_the_ground_floor():
    for path in modules("common"):
        foreign = {name for name in project_imports(path) if name.split(".")[0] not in GROUND}
        assert not foreign, f"{path.relative_to(ROOT)} imports {sorted(foreign)}"


BEHAVIOUR = ("numba", "importlib", "weakref", "inspect")
"""What a module holding behaviour imports and one of records and names never needs: compiled
kernels, loading user code, caches beside the records (`records/__init__` imports its own
submodules lazily, by name)."""


def test_records_hold_data_and_names_only():
    for path in modules("records"):
        tree = ast.parse(path.read_text())
        imported = {
            alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names
        }
        imported |= {node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        behaviour = {name for name in imported if name.split(".")[0] in BEHAVIOUR}
        assert behaviour <= ({"importlib"} if path.name == "__init__.py" else set()), (
            f"{path.name}: {behaviour}"
        )
        caches = [
            target.id
            for node in tree.body
            if isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(node.value, ast.Dict | ast.Set)
            for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
            if isinstance(target, ast.Name)
        ]
        assert not caches, f"{path.relative_to(ROOT)} keeps state at module level: {caches}"


def test_stack_folders_are_known_floors():
    folders = {path.name for path in (ROOT / "stack").iterdir() if (path / "__init__.py").is_file()}
    assert folders == {*STACK_FLOORS, "deepcars"}


@pytest.mark.parametrize("floor", [*STACK_FLOORS, "deepcars"])
def test_stack_imports_point_downwards(floor):
    below = STACK_FLOORS[: STACK_FLOORS.index(floor)] if floor in STACK_FLOORS else ("runtime",)
    below += ("deepcars",) if floor == "apps" else ()
    allowed = {*below, floor}
    for path in modules(f"stack/{floor}"):
        parts = {name: name.split(".") for name in project_imports(path)}
        upward = {
            name
            for name, part in parts.items()
            if part[0] == "stack" and part[1:2] and part[1] not in allowed
        }
        assert not upward, f"{path.relative_to(ROOT)} imports {sorted(upward)}"


ONE_ROLE_FOLDERS = (
    "runtime",
    "worlds",
    "settings",
    "rrd",
    "results",
    "fault",
    "loop",
    "batch",
    "agents",
    "runs",
    "assessment",
)
"""The folders the run core was cut into (once `stack/core`, 4.1k lines); `apps` (a module per
command), `sim` (three backends) and `training` are held by `MAX_LINES` per module instead."""


@pytest.mark.parametrize("floor", ONE_ROLE_FOLDERS)
def test_no_stack_folder_is_a_catch_all(floor):
    lines = sum(len(path.read_text().splitlines()) for path in modules(f"stack/{floor}"))
    assert lines <= MAX_FOLDER_LINES, f"stack/{floor} has {lines} lines"


def test_no_module_is_longer_than_a_sitting():
    for package in PROJECT:
        for path in modules(package):
            lines = len(path.read_text().splitlines())
            assert lines <= MAX_LINES, f"{path.relative_to(ROOT)} has {lines} lines"


def test_every_registered_name_has_an_implementation():
    from controllers.config import ControllerConfig
    from controllers.tracker import make_controller
    from perception.grid import OccupancyGridBuilder
    from records import BACKENDS, CONTROLLER_NAMES, ENCODINGS, ROADS, EgoState, GridConfig, Reference
    from stack.sim.highway import ENV_IDS
    from tests.helpers import scene

    assert tuple(ENV_IDS) == ROADS and all(tuple(ids) == BACKENDS for ids in ENV_IDS.values())
    state, reference = EgoState(d=0.3, heading=0.01, speed=25.0), Reference(1.0, 0.5, 0.0, set_speed=25.0)
    laws = set()
    for name in CONTROLLER_NAMES:
        controller = make_controller(ControllerConfig(type=name), 1 / 15)
        actuation = controller.step(state, reference)
        assert math.isfinite(actuation.steering) and math.isfinite(actuation.acceleration), name
        assert len(controller.solve_times) == 1, name
        laws.add((type(controller), type(getattr(controller, "lateral", None))))
    assert len(laws) == len(CONTROLLER_NAMES), "two controller names build the same controller"
    builder = OccupancyGridBuilder(GridConfig())
    grid = builder.build(scene(3, (0.0, 1), [(15.0, 4.0)]))
    for encoding in ENCODINGS:
        assert builder.space(encoding, 3).contains(
            grid.encode(encoding).astype(builder.space(encoding, 3).dtype)
        )
