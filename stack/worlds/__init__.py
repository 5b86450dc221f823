"""What a run can name to choose its world: the named scenarios (`scenarios`, one YAML file each,
`drivestack scenarios`) and the traffic's driver populations (`drivers`, `drivers.yaml`)."""
