"""An archive's files as an import reads them (``archives.imports``): which member holds each
of DeepRacer's files, and their text, JSON and YAML, each refused in words when it cannot be read.
"""

from __future__ import annotations

import json

import yaml

from archives import exports
from common import documents
from common.refusals import Refused


class Members(dict[str, bytes | None]):
    """An archive's files by relative path: the contents of those an import reads, None for the
    others; ``top`` is the single top-level folder taken off their paths ('' when none);
    ``over``: the paths of the training history's files left unread, being over their limit
    (the model imports without its history)."""

    top = ""
    over: frozenset[str] = frozenset()


NOT_AN_ARCHIVE = (
    "This file is not a .tar.gz model archive, or it is damaged: choose the "
    "virtualmodel-<name>.tar.gz downloaded from a Pitlane model's page, or a model "
    "downloaded from DeepRacer."
)


class ImportRefused(Refused):
    """The archive cannot be imported; the message says why, in a racer's words."""


# Where each of DeepRacer's files is looked for, first found first: at the root (a Pitlane
# export, a folder of DeepRacer's files packed as they are), or where DeepRacer's training keeps
# it under the model's prefix, as DeepRacer for Cloud uploads a model: model/model_metadata.json,
# ip/hyperparameters.json (simapp bundle/markov/boto/s3/constants.py:43,50, 01f5f01).
PLACES = {
    "model_metadata.json": ("model_metadata.json", "model/model_metadata.json"),
    "hyperparameters.json": ("hyperparameters.json", exports.HYPERPARAMETERS),
    "reward_function.py": ("reward_function.py",),
    "training_params.yaml": ("training_params.yaml",),
}


def member_place(members: Members, name: str) -> str:
    """Where the archive has DeepRacer's file ``name`` (``PLACES``); its first place if nowhere."""
    return next((path for path in PLACES[name] if path in members), PLACES[name][0])


def member_text(members: Members, path: str) -> str | None:
    data = members.get(path)
    if data is None:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ImportRefused(f"{path} is not UTF-8 text.") from None


def member_json(members: Members, path: str) -> dict | None:
    text = member_text(members, path)
    if text is None:
        return None
    try:
        document = documents.json_loads(text)
    except documents.Unreadable as unreadable:
        raise ImportRefused(f"{path} cannot be read: {unreadable}.") from None
    except json.JSONDecodeError as error:
        raise ImportRefused(
            f"{path} is not valid JSON (line {error.lineno}, column {error.colno})."
        ) from None
    except ValueError:
        raise ImportRefused(f"{path} is not valid JSON.") from None
    if not isinstance(document, dict):
        raise ImportRefused(f"{path} must hold a JSON object.")
    return document


def member_yaml(members: Members, path: str) -> dict:
    text = member_text(members, path)
    if text is None:
        return {}
    try:
        document = documents.yaml_load(text)
    except documents.Unreadable as unreadable:
        raise ImportRefused(f"{path} cannot be read: {unreadable}.") from None
    except yaml.YAMLError:
        raise ImportRefused(f"{path} is not valid YAML.") from None
    return document if isinstance(document, dict) else {}
