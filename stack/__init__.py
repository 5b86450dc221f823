"""drivestack's top layer: the closed loop, the highway-env adapter, configs, envs and the CLI."""

from stack.envs import register_envs

register_envs()
