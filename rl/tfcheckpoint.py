"""TensorFlow checkpoints (the V2 "tensor bundle"), read without TensorFlow.

A DeepRacer model's weights arrive as the checkpoint rl_coach's saver writes
(``<N>_Step-<M>.ckpt.index`` and ``.ckpt.data-00000-of-00001``; simapp bundle/markov/boto/s3/
files/checkpoint_files/rl_coach_checkpoint.py). The ``.index`` file is a table in LevelDB's format
(tensorflow/core/lib/io/format.h, block.cc, table.cc) mapping each tensor's name to a
``BundleEntryProto`` (tensorflow/core/protobuf/tensor_bundle.proto): its dtype, shape, and where
its bytes lie in the data file (shard, offset, size); the empty key holds the
``BundleHeaderProto``. The data file is the tensors' raw little-endian bytes, one after another.

Both files come from a racer's upload: every length and offset is checked against the bytes there
are, and anything that does not add up is ``Unreadable``, never an exception of another kind.

``write`` makes one, as TensorFlow's ``BundleWriter`` does (tensor_bundle.cc): the header under the
empty key, then each tensor under its name in ascending order, its bytes in the data file with
their masked CRC32C (TensorFlow's reader refuses a tensor whose sum does not match, and a block
whose trailer's does not: format.cc ReadBlock), in one data block of LevelDB's table.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

import google_crc32c
import numpy as np
from google.protobuf.message import DecodeError

from rl import tfgraph

MAGIC = 0xDB4775248B80FB57  # LevelDB's table magic (format.h kTableMagicNumber)
FOOTER = 48  # two block handles padded to 40 bytes, then the magic
NO_COMPRESSION = 0  # a block's trailer type; TensorFlow writes bundle indexes uncompressed
RESTART_INTERVAL = 16  # keys between a data block's restart points (LevelDB's options.h)
CRC_MASK = 0xA282EAD8  # lib/hash/crc32c.h Mask: a sum stored beside the bytes it sums
SUFFIX_INDEX = ".index"
SUFFIX_DATA = ".data-00000-of-00001"  # one shard: what a single saver writes


class Unreadable(ValueError):
    """The bytes are not a checkpoint this reader can read; the message says why."""


@dataclass(frozen=True)
class Entry:
    """Where one tensor lies: in shard ``shard`` of the data, ``size`` bytes at ``offset``."""

    dtype: np.dtype
    shape: tuple[int, ...]
    shard: int
    offset: int
    size: int


# types.proto: the dtypes a network's weights and its bookkeeping use
_DTYPES = {1: "<f4", 2: "<f8", 3: "<i4", 9: "<i8", 19: "<f2", 10: "|b1"}


def entries(index: bytes) -> dict[str, Entry]:
    """Every tensor a ``.index`` file lists, by name."""
    if len(index) < FOOTER or struct.unpack_from("<Q", index, len(index) - 8)[0] != MAGIC:
        raise Unreadable("it is not a TensorFlow checkpoint index")
    footer = memoryview(index)[len(index) - FOOTER :]
    _metaindex, at = _handle(footer, 0)
    top, _ = _handle(footer, at)
    found: dict[str, Entry] = {}
    for _, handle in _block(index, top):
        for key, value in _block(index, _handle(handle, 0)[0]):
            name = key.decode("utf-8", "replace")
            try:
                if not name:
                    header = tfgraph.BundleHeaderProto.FromString(value)
                    if header.num_shards > 1 or header.endianness != 0:
                        raise Unreadable("its weights are split in shards or big-endian")
                    continue
                proto = tfgraph.BundleEntryProto.FromString(value)
            except DecodeError:
                raise Unreadable(f"its entry for {name} is damaged") from None
            if proto.slices:
                raise Unreadable(f"{name} is saved in slices")
            if proto.dtype not in _DTYPES:
                continue  # strings and other bookkeeping: never a weight
            found[name] = Entry(
                dtype=np.dtype(_DTYPES[proto.dtype]),
                shape=tuple(int(dim.size) for dim in proto.shape.dim),
                shard=proto.shard_id,
                offset=proto.offset,
                size=proto.size,
            )
    return found


def read(
    listed: dict[str, Entry], names: Iterable[str], data: Callable[[int, int], bytes]
) -> dict[str, np.ndarray]:
    """The tensors ``names`` of those ``listed``, their bytes read by ``data(offset, size)`` in
    ascending offset (so that a compressed archive is read once, forwards)."""
    tensors = {}
    for name in sorted(set(names), key=lambda name: listed[name].offset):
        entry = listed[name]
        count = int(np.prod(entry.shape, dtype=np.int64))
        if entry.shard != 0 or entry.size != count * entry.dtype.itemsize or entry.offset < 0:
            raise Unreadable(f"{name}'s entry does not add up")
        raw = data(entry.offset, entry.size)
        if len(raw) != entry.size:
            raise Unreadable(f"the data file ends before {name}")
        tensors[name] = np.frombuffer(raw, entry.dtype).reshape(entry.shape).astype(np.float32)
    return tensors


def write(tensors: Mapping[str, np.ndarray]) -> tuple[bytes, bytes]:
    """The ``.index`` and ``.data-00000-of-00001`` bytes of a checkpoint holding ``tensors``, each
    as float32."""
    header = tfgraph.BundleHeaderProto(num_shards=1, endianness=0)
    header.version.producer = 1  # tensor_bundle.h kTensorBundleVersion
    records, data = [(b"", header.SerializeToString())], bytearray()
    for key in sorted(name.encode() for name in tensors):
        raw = np.ascontiguousarray(tensors[key.decode()], dtype="<f4").tobytes()
        entry = tfgraph.BundleEntryProto(dtype=1, offset=len(data), size=len(raw))
        entry.crc32c = _masked(raw)
        for size in np.shape(tensors[key.decode()]):
            entry.shape.dim.add(size=int(size))
        records.append((key, entry.SerializeToString()))
        data += raw
    index = bytearray()

    def placed(block: bytes) -> bytes:
        """``block`` with its trailer appended to the index; its handle."""
        handle = _encoded(len(index)) + _encoded(len(block))
        index.extend(block + bytes([NO_COMPRESSION]))
        index.extend(struct.pack("<I", _masked(block + bytes([NO_COMPRESSION]))))
        return handle

    top = placed(_block_of(records, RESTART_INTERVAL))
    metaindex = placed(_block_of([], 1))
    # The index block names each data block by a key at least its last one's.
    handles = placed(_block_of([(records[-1][0], top)], 1))
    footer = (metaindex + handles).ljust(FOOTER - 8, b"\0") + struct.pack("<Q", MAGIC)
    return bytes(index + footer), bytes(data)


def _masked(data: bytes) -> int:
    crc = google_crc32c.value(data)
    return ((((crc >> 15) | (crc << 17)) & 0xFFFFFFFF) + CRC_MASK) & 0xFFFFFFFF


def _encoded(value: int) -> bytes:
    """``value`` as a varint."""
    out = bytearray()
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    return bytes([*out, value])


def _block_of(records: list[tuple[bytes, bytes]], interval: int) -> bytes:
    """A table block of ``records`` (ascending keys): each key shares its prefix with the one
    before, except at a restart point every ``interval`` records."""
    out, restarts, last = bytearray(), [], b""
    for number, (key, value) in enumerate(records):
        shared = 0
        if number % interval:
            while shared < min(len(key), len(last)) and key[shared] == last[shared]:
                shared += 1
        else:
            restarts.append(len(out))
        out += _encoded(shared) + _encoded(len(key) - shared) + _encoded(len(value))
        out += key[shared:] + value
        last = key
    restarts = restarts or [0]
    return bytes(out) + struct.pack(f"<{len(restarts) + 1}I", *restarts, len(restarts))


def _varint(buffer, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if at >= len(buffer) or shift > 63:
            raise Unreadable("a length in it runs past its end")
        byte = buffer[at]
        value |= (byte & 0x7F) << shift
        at, shift = at + 1, shift + 7
        if not byte & 0x80:
            return value, at


def _handle(buffer, at: int) -> tuple[tuple[int, int], int]:
    """A BlockHandle (offset, size) at ``at``, and where the next field starts."""
    offset, at = _varint(buffer, at)
    size, at = _varint(buffer, at)
    return (offset, size), at


def _block(index: bytes, handle: tuple[int, int]):
    """The (key, value) pairs of the block at ``handle``: keys share prefixes with the one
    before; the block ends with its restart offsets and their count, then a 5-byte trailer
    (compression type, checksum) after it."""
    offset, size = handle
    if offset < 0 or size < 4 or offset + size + 5 > len(index):
        raise Unreadable("a block in it lies outside the file")
    if index[offset + size] != NO_COMPRESSION:
        raise Unreadable("its blocks are compressed")
    block = memoryview(index)[offset : offset + size]
    restarts = struct.unpack_from("<I", block, size - 4)[0]
    end = size - 4 - 4 * restarts
    if end < 0:
        raise Unreadable("a block in it is damaged")
    key, at = b"", 0
    while at < end:
        shared, at = _varint(block, at)
        unshared, at = _varint(block, at)
        length, at = _varint(block, at)
        if shared > len(key) or at + unshared + length > end:
            raise Unreadable("a block in it is damaged")
        key = key[:shared] + bytes(block[at : at + unshared])
        at += unshared
        yield key, bytes(block[at : at + length])
        at += length
