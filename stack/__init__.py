"""drivestack's top layer: the closed loop, the highway-env adapter, configs, envs and the CLI."""

from stack.sim.envs import register_envs

register_envs()
