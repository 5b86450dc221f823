"""drivestack's top layer, over the layers `perception`, `planner` and `controllers`, in floors that
import only those below them: the process runtime (`runtime`), the settings a run is told
(`settings`), the simulator (`sim`), the recording's file (`rrd`), the episode record (`results`),
the closed loop (`loop`), the agents that need it (`agents`), seeded episodes (`runs`), the R157
safety assessment (`assessment`), training (`training`) and the applications (`apps`, the
`drivestack` CLI); the paper's grid world (`deepcars`) stands alone (docs/architecture.md).

The public API, imported on first use so `import stack` stays light:

- `load_config(path, **overrides)` / `build_config(data, **overrides)` -> `RunConfig`;
- `run(config)` -> `RunResults` (every episode of a config) and `run_episode(config, episode)`;
- `world_state(env)` -> `WorldState` of any highway-env env, for `perception.OccupancyGridBuilder`.

Importing `stack` registers its gymnasium envs (`drivestack/VectorHighway-v0`, ...), without
importing gymnasium itself: at once if it is imported, else when it is.
"""

import os
from importlib import import_module
from typing import Any

import common.numba_cache  # noqa: F401  numba's cache folder is set before anything here compiles

os.environ.setdefault("MPLBACKEND", "Agg")  # figures are written to files; chosen here, once

from stack.sim.envs import register_when_imported  # noqa: E402

register_when_imported()

_PUBLIC = {
    "load_config": "stack.settings.run",
    "build_config": "stack.settings.run",
    "RunConfig": "stack.settings.run",
    "run": "stack.runs.episodes",
    "run_episode": "stack.runs.episodes",
    "world_state": "stack.sim.highway",
}
__all__ = list(_PUBLIC)


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        return getattr(import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'stack' has no attribute {name!r}")
