"""Checks of config data beyond pydantic's: booleans and numbers kept apart, and the first key two
configs differ in (what a resumed training may not change)."""

from __future__ import annotations

import types
import typing
from typing import Any

from pydantic import BaseModel


def boolean_mismatch(model: type[BaseModel], data: object, prefix: str = "") -> tuple[str, str] | None:
    """(dotted key, why) of the first value in `data` that is a boolean where `model` takes a
    number, or a number where it takes a boolean, in its sections and in lists, pairs and mappings
    alike (`highway.traffic.classes.0.share`): YAML reads `yes`, `on` and `true` as booleans, and
    pydantic would quietly turn them into 1 (and 1 into true). None when there is none."""
    if not isinstance(data, dict):
        return None
    for name, value in data.items():
        field = model.model_fields.get(str(name))
        if field is not None and (found := _mismatch(field.annotation, value, f"{prefix}{name}")):
            return found
    return None


def _mismatch(kind: Any, value: object, key: str) -> tuple[str, str] | None:
    """`boolean_mismatch` of one `value` that the type `kind` describes."""
    union = typing.get_origin(kind) in (typing.Union, types.UnionType)
    kinds = typing.get_args(kind) if union else (kind,)
    sections = [k for k in kinds if isinstance(k, type) and issubclass(k, BaseModel)]
    if sections and isinstance(value, dict):
        return boolean_mismatch(sections[0], value, f"{key}.")
    for container in (k for k in kinds if typing.get_origin(k) in (tuple, list, dict)):
        if (items := _items(container, value)) is not None:
            return next((found for k, v, name in items if (found := _mismatch(k, v, f"{key}.{name}"))), None)
    numbers = int in kinds or float in kinds
    if isinstance(value, bool) and bool not in kinds and numbers:
        return key, f"expected a number, got a boolean ({str(value).lower()})"
    if type(value) in (int, float) and bool in kinds and not numbers:
        return key, f"expected true or false, got a number ({value})"
    return None


def _items(container: Any, value: object) -> list[tuple[Any, object, object]] | None:
    """(element type, element, index or key) of `value` as the list, tuple or mapping type
    `container` describes; None when `value` is not of its shape."""
    arguments = typing.get_args(container)
    if typing.get_origin(container) is dict:
        kind = arguments[1] if len(arguments) == 2 else Any
        return [(kind, v, k) for k, v in value.items()] if isinstance(value, dict) else None
    if not isinstance(value, list | tuple):
        return None
    if (len(arguments) == 2 and arguments[1] is Ellipsis) or typing.get_origin(container) is list:
        kinds = [arguments[0] if arguments else Any] * len(value)
    else:
        kinds = list(arguments)
    return [(k, v, index) for index, (k, v) in enumerate(zip(kinds, value, strict=False))]


def first_change(old: Any, new: Any, key: str = "") -> tuple[str, Any, Any] | None:
    """The first dotted key whose value differs between two config dumps (`model_dump`), with
    its old and new values; None when they are equal."""
    if isinstance(old, dict) and isinstance(new, dict):
        for name in [*old, *(k for k in new if k not in old)]:
            if found := first_change(old.get(name), new.get(name), f"{key}.{name}" if key else name):
                return found
        return None
    return None if old == new else (key, old, new)
