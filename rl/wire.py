"""Messages as bytes: msgpack maps, never pickle, read strictly. The sandbox's protocol frames
them between a worker and its child (``sandbox.protocol``); an episode crosses Redis as one."""

from __future__ import annotations

import socket
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


_LENGTH = 4  # [bytes] before each message on a stream socket: its size, big-endian
MAX_MESSAGE = 256 * 1024 * 1024  # [bytes]: the 5-layer network's weights are about 55 MB
MAX_FDS = 4  # file descriptors that may come with a message


def send_message(connection, message: dict[str, Any], fds=()) -> None:
    """``message`` on the stream socket ``connection``, with ``fds`` (``SCM_RIGHTS``)."""
    body = encode(message)
    framed = len(body).to_bytes(_LENGTH, "big") + body
    sent = socket.send_fds(connection, [framed], list(fds)) if fds else 0
    connection.sendall(framed[sent:])


def receive_message(connection) -> tuple[dict[str, Any] | None, list[int]]:
    """The next message on the stream socket ``connection`` and the descriptors that came with
    it; (None, []) where the peer closed between messages."""
    head, fds, _, _ = socket.recv_fds(connection, _LENGTH, MAX_FDS)
    if not head:
        return None, []
    head += _exactly(connection, _LENGTH - len(head))
    size = int.from_bytes(head, "big")
    if size > MAX_MESSAGE:
        raise ProtocolError(f"a {size}-byte message is over the {MAX_MESSAGE}-byte limit")
    return decode(_exactly(connection, size)), list(fds)


def _exactly(connection, size: int) -> bytes:
    buffer = bytearray(size)
    view, done = memoryview(buffer), 0
    while done < size:
        count = connection.recv_into(view[done:])
        if not count:
            raise ProtocolError("the connection ended inside a message")
        done += count
    return bytes(buffer)
