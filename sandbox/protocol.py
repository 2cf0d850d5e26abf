"""Messages between a worker and its sandbox child: length-prefixed msgpack frames over pipes.

msgpack, never pickle: the child runs untrusted code, and unpickling what it sends would hand it
the worker. The reader also bounds the size of a frame, so a child cannot make the worker
allocate without limit.
"""

from __future__ import annotations

import os
import select
import struct
import time
from typing import Any, BinaryIO

from rl.wire import ProtocolError, encode
from rl.wire import decode as unpack

HEADER = struct.Struct("!I")
MAX_FRAME = 256 * 1024 * 1024  # [bytes]: the 5-layer network's weights are about 55 MB


class Late(TimeoutError):
    """The other side did not finish a frame (or take one) by the deadline."""


def pack(message: dict[str, Any]) -> bytes:
    body = encode(message)
    return HEADER.pack(len(body)) + body


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


def read_frame_by(fd: int, deadline: float, limit: int) -> dict[str, Any] | None:
    """The next message on the non-blocking ``fd``, whole by ``deadline`` (``time.monotonic()``);
    None where the stream ends before its first byte. ``Late`` when the deadline passes,
    ``ProtocolError`` for a frame over ``limit`` bytes or broken off: however the writer
    misbehaves (a frame begun and never finished included), this returns by the deadline."""
    header = _read_by(fd, HEADER.size, deadline)
    if header is None:
        return None
    (size,) = HEADER.unpack(header)
    if size > limit:
        raise ProtocolError(f"a {size}-byte frame is over the {limit}-byte limit")
    body = _read_by(fd, size, deadline)
    if body is None:
        raise ProtocolError("the stream ended inside a frame")
    return unpack(body)


def write_by(fd: int, data: bytes, deadline: float) -> None:
    """Write all of ``data`` to the non-blocking ``fd`` by ``deadline``, or raise ``Late``: a
    reader that stops reading cannot block the writer."""
    view, done = memoryview(data), 0
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    while done < len(data):
        try:
            done += os.write(fd, view[done : done + 65536])
            continue
        except BlockingIOError:
            pass
        if not poller.poll(_remaining_ms(deadline)):
            raise Late("the reader took nothing by the deadline")


def _read_by(fd: int, size: int, deadline: float) -> bytes | None:
    buffer = bytearray()
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    while len(buffer) < size:
        try:
            chunk = os.read(fd, min(size - len(buffer), 1 << 20))
        except BlockingIOError:
            if not poller.poll(_remaining_ms(deadline)):
                raise Late("no whole frame by the deadline") from None
            continue
        if not chunk:
            if not buffer:
                return None
            raise ProtocolError("the stream ended inside a frame")
        buffer += chunk
    return bytes(buffer)


def _remaining_ms(deadline: float) -> int:
    remaining = deadline - time.monotonic()
    if remaining <= 0:
        raise Late("the deadline passed")
    return max(1, int(remaining * 1000))
