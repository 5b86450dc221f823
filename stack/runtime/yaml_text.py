"""YAML as drivestack reads it (config files, sweep files, `--set` values): safe, no aliases, no
duplicate keys, bounded nesting."""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

import yaml

QUOTED_KEY_CHARS = 80
"""Longest quote of a duplicate key in an error message [characters]."""

MAX_YAML_DEPTH = 64
"""Deepest nesting of sections and lists a config or `--set` value may have."""


class _NoAliasLoader(yaml.SafeLoader):
    """PyYAML's safe loader without anchors and aliases, so a small file cannot expand into a huge
    document (a "billion laughs"), without duplicate keys in a mapping (PyYAML keeps the last one
    silently) and nested at most `MAX_YAML_DEPTH` deep (deeper ends in Python's recursion limit)."""

    _depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent) or getattr(self.peek_event(), "anchor", None):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, "anchors and aliases (&, *) are not accepted", event.start_mark
            )
        if self._depth >= MAX_YAML_DEPTH:
            raise yaml.composer.ComposerError(
                None, None, f"nested more than {MAX_YAML_DEPTH} deep", self.peek_event().start_mark
            )
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, Hashable):
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"key {str(key)[:QUOTED_KEY_CHARS]!r} given twice", key_node.start_mark
                    )
                seen.add(key)
        return super().construct_mapping(node, deep)


def strict_yaml(text: str) -> Any:
    """`text` as YAML by the rules of `_NoAliasLoader`; yaml.YAMLError otherwise."""
    return yaml.load(text, Loader=_NoAliasLoader)
