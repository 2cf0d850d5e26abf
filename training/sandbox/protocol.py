"""Messages between a worker and its sandbox child: length-prefixed msgpack frames over pipes.

msgpack, never pickle: the child runs untrusted code, and unpickling what it sends would hand it
the worker. The reader also bounds the size of a frame, so a child cannot make the worker
allocate without limit.
"""

from __future__ import annotations

import struct
from typing import Any, BinaryIO

import msgpack

HEADER = struct.Struct("!I")
MAX_FRAME = 256 * 1024 * 1024  # [bytes]: the 5-layer network's weights are about 55 MB


class ProtocolError(ValueError):
    """The other side sent something that is not a frame of ours."""


def pack(message: dict[str, Any]) -> bytes:
    body = msgpack.packb(message, use_bin_type=True)
    return HEADER.pack(len(body)) + body


def unpack(body: bytes) -> dict[str, Any]:
    try:
        message = msgpack.unpackb(body, raw=False, strict_map_key=True)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as error:
        raise ProtocolError(f"not a message: {error}") from None
    if not isinstance(message, dict):
        raise ProtocolError("a message is a map")
    return message


def read_frame(stream: BinaryIO) -> dict[str, Any] | None:
    """The next message, or None where the stream ends between messages (blocking)."""
    header = _read_exactly(stream, HEADER.size)
    if header is None:
        return None
    (size,) = HEADER.unpack(header)
    if size > MAX_FRAME:
        raise ProtocolError(f"a {size}-byte frame is over the {MAX_FRAME}-byte limit")
    body = _read_exactly(stream, size)
    if body is None:
        raise ProtocolError("the stream ended inside a frame")
    return unpack(body)


def _read_exactly(stream: BinaryIO, size: int) -> bytes | None:
    """``size`` bytes; None at the end of the stream before the first byte. Reads into one
    buffer, so an unbuffered stream (which returns what the pipe holds) costs no copies."""
    buffer = bytearray(size)
    view, done = memoryview(buffer), 0
    while done < size:
        count = stream.readinto(view[done:])
        if not count:
            if done == 0:
                return None
            raise ProtocolError("the stream ended inside a frame")
        done += count
    return bytes(buffer)
