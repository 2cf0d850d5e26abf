"""Messages as bytes: msgpack maps, never pickle, read strictly. The sandbox's protocol frames
them between a worker and its child (``sandbox.protocol``); an episode crosses Redis as one, its
arrays each a map of dtype, shape and bytes (``encode_arrays``). No Redis here: the sandbox child,
which encodes its episodes, never loads a client it cannot use."""

from __future__ import annotations

import math
import socket
import zlib
from typing import Any

import msgpack
import numpy as np


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


# Arrays, as a message carries them


def encode_arrays(arrays: dict[str, np.ndarray], *, compress: bool = True) -> dict:
    """Each of ``arrays`` as a message carries it: dtype, shape and bytes, compressed (zlib,
    level 1) for Redis unless ``compress`` is False (a pipe gains nothing: ``sandbox.served``)."""
    contiguous = {name: np.ascontiguousarray(array) for name, array in arrays.items()}
    return {
        name: {
            "dtype": str(a.dtype),
            "shape": list(a.shape),
            "data": zlib.compress(a.tobytes(), 1) if compress else a.tobytes(),
        }
        for name, a in contiguous.items()
    }


def decode_array(
    encoded, dtype: str, shape: tuple[int | None, ...], *, compressed: bool = True
) -> np.ndarray:
    """The array ``encode_arrays`` made (``compressed`` as it was): of ``dtype`` and ``shape``
    (None: any length), each size a whole number under 2**31, with exactly its shape's bytes;
    else ``ProtocolError`` (a ValueError). Uncompressed, a writable copy (for torch)."""
    if not isinstance(encoded, dict) or encoded.get("dtype") != dtype:
        raise ProtocolError(f"expected {dtype} data")
    declared = encoded.get("shape")
    if (
        not isinstance(declared, list)
        or len(declared) != len(shape)
        or not all(type(size) is int and 0 <= size < 2**31 for size in declared)
        or any(want is not None and want != got for want, got in zip(shape, declared, strict=True))
    ):
        raise ProtocolError(f"expected shape {shape}, got {declared}")
    size, data = math.prod(declared) * np.dtype(dtype).itemsize, encoded.get("data")
    try:  # never inflated more than a byte past the shape's
        if isinstance(data, bytes) and compressed:
            data = zlib.decompressobj().decompress(data, min(size + 1, 1 << 62))
    except zlib.error as error:
        raise ProtocolError(f"an array's bytes that do not inflate ({error})") from None
    if not isinstance(data, bytes) or len(data) != size:
        raise ProtocolError("an array whose bytes do not match its shape")
    return np.frombuffer(data if compressed else bytearray(data), dtype=dtype).reshape(declared)
