"""Agents that need the closed loop itself, so they cannot live in `planner` (which never imports
`stack`): the `oracle`, which plans on copies of the loop."""
