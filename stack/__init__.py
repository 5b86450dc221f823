"""drivestack's top layer: the closed loop, the highway-env adapter, configs and the CLI."""
