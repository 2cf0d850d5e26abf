"""Messages as bytes: msgpack maps, never pickle, read strictly. The sandbox's protocol frames
them between a worker and its child (``sandbox.protocol``); an episode crosses Redis as one."""

from __future__ import annotations

from typing import Any

import msgpack


class ProtocolError(ValueError):
    """The other side sent something that is not a message of ours."""


def encode(message: dict[str, Any]) -> bytes:
    return msgpack.packb(message, use_bin_type=True)


def decode(body: bytes) -> dict[str, Any]:
    """The map in ``body``; ``ProtocolError`` when it holds anything else."""
    try:
        message = msgpack.unpackb(body, raw=False, strict_map_key=True)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as error:
        raise ProtocolError(f"not a message: {error}") from None
    if not isinstance(message, dict):
        raise ProtocolError("a message is a map")
    return message
