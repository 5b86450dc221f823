"""Checks of config data beyond pydantic's: booleans and numbers kept apart, and the first key two
configs differ in (what a resumed training may not change)."""

from __future__ import annotations

import typing
from typing import Any

from pydantic import BaseModel


def boolean_mismatch(model: type[BaseModel], data: object, prefix: str = "") -> tuple[str, str] | None:
    """(dotted key, why) of the first value in `data` that is a boolean where `model` takes a
    number, or a number where it takes a boolean: YAML reads `yes`, `on` and `true` as booleans,
    and pydantic would quietly turn them into 1 (and 1 into true). None when there is none."""
    if not isinstance(data, dict):
        return None
    for name, value in data.items():
        field = model.model_fields.get(str(name))
        if field is None:
            continue
        kinds = typing.get_args(field.annotation) or (field.annotation,)
        key = f"{prefix}{name}"
        sections = [kind for kind in kinds if isinstance(kind, type) and issubclass(kind, BaseModel)]
        if sections and isinstance(value, dict):
            if found := boolean_mismatch(sections[0], value, f"{key}."):
                return found
        elif isinstance(value, bool) and bool not in kinds and (int in kinds or float in kinds):
            return key, f"expected a number, got a boolean ({str(value).lower()})"
        elif type(value) in (int, float) and bool in kinds:
            return key, f"expected true or false, got a number ({value})"
    return None


def first_change(old: Any, new: Any, key: str = "") -> tuple[str, Any, Any] | None:
    """The first dotted key whose value differs between two config dumps (`model_dump`), with
    its old and new values; None when they are equal."""
    if isinstance(old, dict) and isinstance(new, dict):
        for name in [*old, *(k for k in new if k not in old)]:
            if found := first_change(old.get(name), new.get(name), f"{key}.{name}" if key else name):
                return found
        return None
    return None if old == new else (key, old, new)
