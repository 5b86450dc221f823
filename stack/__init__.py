"""drivestack's top layer: the simulator (`sim`), the run core (`core`), the applications
(`apps`, the `drivestack` CLI) and the paper's grid world (`deepcars`), over the layers
`perception`, `planner` and `controllers`."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")  # figures are written to files; chosen here, once

from stack.sim.envs import register_envs  # noqa: E402

register_envs()
