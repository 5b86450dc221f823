"""The record types every layer shares, and the names of every swappable part.

`stack`, `perception`, `planner` and `controllers` import this package and nothing of each other
below `stack`. It holds plain data: the world snapshot (`WorldState`), the decision (`Command`),
the grid an agent is shown (`GridConfig`), and what flows through one control tick (`EgoState`,
`Reference`, `Actuation`). Behaviour stays in the layers; only small derived views live here.
Import from `records` itself; the submodules only keep each part short.
"""

from records.grid import EGO_HEADING_SCALE, MAX_LANES, MAX_SPEED, SIDE_LANES_SEEN, GridConfig, lane_code_bits
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
    "lane_curvature",
    "one_of",
    "unknown_name",
]
