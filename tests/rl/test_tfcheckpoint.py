"""TensorFlow checkpoints written without TensorFlow read back as written, and are refused with
words when damaged: the writer's table holds more keys than one restart interval, shares their
prefixes and sums its blocks (TensorFlow's own reading of them: tests/archives/
test_deepracer_on_aws.py)."""

import struct

import numpy as np
import pytest

from rl import tfcheckpoint


def tensors() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    found = {
        f"main_level/agent/main/online/network_1/layer_{n:02d}/kernel": rng.normal(size=(3, n + 1))
        for n in range(40)  # past RESTART_INTERVAL: keys share prefixes between restarts
    }
    return found | {"a/policy_log_std": np.full((1, 2), -0.5), "z/bias": np.arange(5.0)}


def test_a_written_checkpoint_reads_back_every_tensor_as_float32():
    written = tensors()
    index, data = tfcheckpoint.write(written)
    listed = tfcheckpoint.entries(index)
    assert set(listed) == set(written)
    assert [listed[name].shape for name in written] == [np.shape(t) for t in written.values()]
    read = tfcheckpoint.read(listed, written, lambda offset, size: data[offset : offset + size])
    for name, tensor in written.items():
        assert read[name].dtype == np.float32
        np.testing.assert_array_equal(read[name], tensor.astype(np.float32))
    assert len(data) == sum(4 * t.size for t in written.values())


def test_a_damaged_index_is_refused_in_words():
    index, _ = tfcheckpoint.write(tensors())
    footer = len(index) - tfcheckpoint.FOOTER
    with pytest.raises(tfcheckpoint.Unreadable, match="not a TensorFlow checkpoint index"):
        tfcheckpoint.entries(index[:-1] + b"\0")
    # the index block's handle pointing past the file
    moved = index[:footer] + struct.pack("<B", 0x7F) * 8 + index[footer + 8 :]
    with pytest.raises(tfcheckpoint.Unreadable):
        tfcheckpoint.entries(moved)
