"""The CLI's checks of plug-in agents and controllers (docs/plugins.md): one line naming the option,
exit code 2, before any episode."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from stack.apps.options import fail

if TYPE_CHECKING:
    from stack.settings.run import RunConfig


def agent_name_or_fail(option: str, value: str | None) -> None:
    """A one-line error (exit 2) unless `value` (None: not given) is an agent name or plug-in."""
    from common.plugins import AGENT_GROUP, checked_name
    from records import AGENT_NAMES

    try:
        if value is not None:
            checked_name("agent", AGENT_NAMES, AGENT_GROUP, value)
    except ValueError as error:
        fail(f"{option}: {error}")


def plugins_or_fail(configs: Sequence[RunConfig], options: Sequence[str]) -> None:
    """Build now each plug-in agent and controller `configs` name (the i-th config's agent set by
    `options[i]`, its controller by --controller), so a plug-in that does not import, build or fit
    its protocol is one line naming the option (exit 2) before any episode."""
    from records import AGENT_NAMES, CONTROLLER_NAMES

    if all(c.planner.agent in AGENT_NAMES and c.controller.type in CONTROLLER_NAMES for c in configs):
        return
    from controllers.tracker import make_controller
    from stack.runs.kept import build_agent

    for config, option in zip(configs, options, strict=False):
        try:
            if config.planner.agent not in AGENT_NAMES:
                build_agent(config, config.seed)
        except ValueError as error:
            fail(f"{option}: {error}")
        try:
            if config.controller.type not in CONTROLLER_NAMES:
                make_controller(config.controller, config.dt, config.sim.plant)
        except ValueError as error:
            fail(f"--controller: {error}")
