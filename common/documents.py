"""JSON and YAML documents that come from outside (an imported archive's files, a training's
metrics), read with their nesting bounded before a parser recurses into it.

Python's ``json`` and PyYAML's composer go one call deeper for each level of lists and objects:
a few hundred kilobytes of ``[[[[`` end in ``RecursionError`` (a server error) rather than in a
refusal, and a document nested near Python's limit breaks whatever walks it next (saving it to a
JSONField, copying it). Files from DeepRacer or Pitlane nest a few levels; ``MAX_DEPTH`` is far
above them and far below Python's limit.
"""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np
import yaml

MAX_DEPTH = 32  # levels of lists and objects
# A JSON string, its escapes included: brackets inside one do not nest.
JSON_STRING = re.compile(r'"[^"\\]*(?:\\.[^"\\]*)*"')
NOT_A_BRACKET = re.compile(r"[^\[\]{}]")


class Unreadable(ValueError):
    """The document cannot be read safely; the message says why, after "it" ("it nests ...")."""


def _too_deep(max_depth: int) -> Unreadable:
    return Unreadable(f"it nests lists or objects over {max_depth} levels deep")


def json_depth(text: str) -> int:
    """How deep JSON ``text`` nests lists and objects, counted without recursing: a running
    count of the brackets outside strings, up at each opening one, down at each closing one."""
    brackets = NOT_A_BRACKET.sub("", JSON_STRING.sub("", text))
    if not brackets:
        return 0
    codes = np.frombuffer(brackets.encode("ascii"), dtype=np.uint8)
    steps = np.where((codes == ord("[")) | (codes == ord("{")), 1, -1)
    return int(np.cumsum(steps).max())


def json_loads(document: str | bytes, *, max_depth: int = MAX_DEPTH) -> Any:
    """``json.loads(document)``, refused with ``Unreadable`` when it nests deeper than
    ``max_depth`` (checked before parsing); ``ValueError`` when it is not JSON."""
    text = document.decode("utf-8", "replace") if isinstance(document, bytes) else document
    if json_depth(text) > max_depth:
        raise _too_deep(max_depth)
    try:
        return json.loads(document)
    except RecursionError:  # a document json reads in another encoding than UTF-8
        raise _too_deep(max_depth) from None


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a node nested deeper than ``max_depth`` before composing it
    (its composer recurses once a level; its scanner and parser do not), and any alias
    (``*name``): an alias lets a document hold itself, or a billion copies of a list, which
    nothing that reads DeepRacer's settings needs."""

    max_depth = MAX_DEPTH
    depth = 0

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            raise Unreadable("it uses a YAML alias (*name)")
        self.depth += 1
        if self.depth > self.max_depth:
            raise _too_deep(self.max_depth)
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


def yaml_load(text: str) -> Any:
    """``yaml.safe_load(text)``, refused with ``Unreadable`` when it nests deeper than
    ``MAX_DEPTH`` or uses an alias; ``yaml.YAMLError`` when it is not YAML."""
    return yaml.load(text, Loader=_BoundedLoader)  # noqa: S506 (a SafeLoader)
