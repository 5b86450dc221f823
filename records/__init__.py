"""The record types every layer shares, and the names of every swappable part.

`stack`, `perception`, `planner` and `controllers` import this package and nothing of each other
below `stack`. It holds plain data: the world snapshot (`WorldState`), the decision (`Command`),
the grid an agent is shown (`GridConfig`), and what flows through one control tick (`EgoState`,
`Reference`, `Actuation`). Data and names only: behaviour stays in the layers, and what two layers
share of it lives beside this package in `common` (plug-in loading, compiled kernels, the ego's
neighbours); a record derives views of its own fields only (`WorldState.ego_state`), with no
cache, kernel or user code. Import from `records` itself; the submodules only keep each part
short, and each is imported on the first use of one of its names (numpy and pydantic with them),
so `import records` stays light for the command line's option texts.
"""

from importlib import import_module
from typing import TYPE_CHECKING, Any

SUBMODULES = ("records.names", "records.tick", "records.world", "records.grid")
"""Where the public names live, searched in this order on a name's first use."""

if TYPE_CHECKING:
    from records.grid import (
        EGO_HEADING_SCALE,
        FEATURES,
        MAX_LANES,
        MAX_SPEED,
        SIDE_LANES_SEEN,
        TRAFFIC_VALUES,
        GridConfig,
        lane_code_bits,
    )
    from records.names import (
        AGENT_NAMES,
        BACKENDS,
        CONTROLLER_NAMES,
        ENCODINGS,
        LEARNED_AGENTS,
        PLANTS,
        POLICY_NAMES,
        ROADS,
        SEED_LIMIT,
        TRAINING_SEED_FLOOR,
        AgentName,
        Backend,
        ControllerName,
        Encoding,
        LearnedAgentName,
        PlantName,
        PolicyName,
        RoadName,
        child_seed,
        drawn_seed,
        one_of,
        unknown_name,
    )
    from records.tick import N_ACTIONS, Actuation, Command, LateralProfile, Reference, clip
    from records.world import EgoState, Lane, Neighbour, WorldState, lane_curvature

__all__ = [
    "AGENT_NAMES",
    "BACKENDS",
    "PLANTS",
    "PlantName",
    "CONTROLLER_NAMES",
    "ENCODINGS",
    "LEARNED_AGENTS",
    "MAX_SPEED",
    "N_ACTIONS",
    "POLICY_NAMES",
    "ROADS",
    "SEED_LIMIT",
    "TRAINING_SEED_FLOOR",
    "Actuation",
    "AgentName",
    "Backend",
    "Command",
    "ControllerName",
    "EgoState",
    "Encoding",
    "GridConfig",
    "Lane",
    "LateralProfile",
    "LearnedAgentName",
    "Neighbour",
    "PolicyName",
    "RoadName",
    "Reference",
    "WorldState",
    "child_seed",
    "clip",
    "drawn_seed",
    "lane_code_bits",
    "MAX_LANES",
    "SIDE_LANES_SEEN",
    "EGO_HEADING_SCALE",
    "FEATURES",
    "TRAFFIC_VALUES",
    "lane_curvature",
    "one_of",
    "unknown_name",
]


def __getattr__(name: str) -> Any:
    """A public name, imported from its submodule on first use and kept here."""
    if name in __all__:
        for module in map(import_module, SUBMODULES):
            if hasattr(module, name):
                globals()[name] = value = getattr(module, name)
                return value
    raise AttributeError(f"module 'records' has no attribute {name!r}")
