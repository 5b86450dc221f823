"""The checks `run` and `compare` make before any work, each refusal one line (exit 2), cheapest
first: the model files, the location, the agents as built, then the folder is taken."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from stack.apps.options import fail

if TYPE_CHECKING:
    from stack.settings.run import RunConfig


def checked_run(
    configs: list[RunConfig], out: Path | None, prefix: str, resuming: bool = False, jobs: int = 1
) -> Path:
    """The results folder of a run of `configs`, after checking (one line, exit 2, before any
    work) each agent's model file with numpy alone, then the location, then each agent as built
    for its road (this imports torch), then taking the folder for this command
    (`stack.apps.folders.claimed`; `prefix` names the command)."""
    from planner.factory import model_path
    from planner.model_check import checked_model
    from stack.runs.model_fit import check_file_fit

    for config in configs:
        try:
            if (path := model_path(config.planner.agent, config.planner.model)) is not None:
                _, metadata = checked_model(path, (config.planner.agent,))
                if metadata.kind != "qtable" and metadata.observation_size is not None:
                    lanes = config.highway.lane_counts
                    check_file_fit(path, metadata, lanes)
        except ValueError as error:
            fail(str(error))
    from stack.apps.folders import claimed, location
    from stack.apps.resume import edited_code, run_owner
    from stack.apps.training import check_jobs

    check_jobs(jobs)
    folder = location(out, prefix)
    from stack.runtime.owner import refusal

    edited = edited_code(configs, folder) if resuming else None
    if why := edited or refusal(folder, run_owner(configs, prefix), resuming):
        fail(why)
    from stack.runs.kept import build_agent

    for config in configs:
        try:
            build_agent(config, config.seed)
        except ValueError as error:
            fail(str(error))
    return claimed(folder, prefix, run_owner(configs, prefix), resuming)
