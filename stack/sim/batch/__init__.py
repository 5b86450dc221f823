"""Many worlds in one process: the traffic of N worlds as [worlds, vehicles] arrays, stepped
together by compiled kernels (`stack.sim.batch.traffic`)."""
