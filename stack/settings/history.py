"""Config keys whose history matters to a run folder: the ones that change how a run is carried
out but not its results (`HOW_NOT_WHAT`), and the ones added after folders were written
(`ADDED_LATER`), so an old folder's `config.yaml` still reproduces and resumes its run."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel

HOW_NOT_WHAT = {"sim": {"batched"}, "train": {"member_jobs"}}
"""Config keys that change how a run is carried out, never its results: left out of the
fingerprint that lets `--resume` go on with a folder (`stack.apps.resume`, `training_owner`)."""
ADDED_LATER: dict[str, dict[str, Any]] = {
    "train": {"overlap": False, "members": 1},
    "planner.safety": {
        "abort_lookahead_s": 0.0,
        "far_lane_gap_m": None,
        "far_lane_leader": False,
        "follower_braking_mps2": None,
        "follower_reaction_s": 0.4,
    },
    "planner": {"change_margin": 0.0},
    "controller": {"cut_in_lookahead_s": 0.0, "weaver_wary_s": 0.0},
}
"""Config keys (by dotted section) added after folders were written, with the value the runs of
those folders had: a resolved config written before the key existed (its section holds every
other key) reads it as that value (`with_former_values`), so its run is reproduced; the key is left
out of the fingerprint while it holds that value, so such a folder still resumes."""


def _section_model(root: type[BaseModel], dotted: str) -> type[BaseModel]:
    model = root
    for part in dotted.split("."):
        model = model.model_fields[part].annotation  # type: ignore[assignment]
    return model


def with_former_values(data: dict[str, Any], root: type[BaseModel]) -> dict[str, Any]:
    """`data` (a config of model `root`) in which each `ADDED_LATER` key missing from a section that
    holds every other key of its model (a resolved config written before the key existed) takes its
    former value."""
    for dotted, former in ADDED_LATER.items():
        parents: list[tuple[dict[str, Any], str]] = []
        node: Any = data
        for part in dotted.split("."):
            parents.append((node, part))
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict):
            continue
        others = set(_section_model(root, dotted).model_fields) - set(former)
        missing = {key: value for key, value in former.items() if key not in node}
        if missing and others <= set(node):
            filled: dict[str, Any] = {**node, **missing}
            for parent, part in reversed(parents):
                filled = {**parent, part: filled}
            data = filled
    return data


def unfingerprinted(config: BaseModel) -> dict[str, Any]:
    """The keys (pydantic's nested form) left out of `config`'s fingerprint: `HOW_NOT_WHAT`, and
    the `ADDED_LATER` ones at their former value."""
    exclude: dict[str, Any] = {section: dict.fromkeys(keys, True) for section, keys in HOW_NOT_WHAT.items()}
    for dotted, former in ADDED_LATER.items():
        values: Any = config
        for part in dotted.split("."):
            values = getattr(values, part)
        node = exclude
        for part in dotted.split("."):
            node = node.setdefault(part, {})
        node.update({key: True for key, value in former.items() if getattr(values, key) == value})
    return exclude
