"""What a run is told, resolved here and nowhere else: the named scenarios, the world's settings (road,
traffic, simulator), the run config, its `train:` section and sweep files; YAML -> validated pydantic
models before any work starts. The layers above read the resolved models; nothing here builds a world."""
