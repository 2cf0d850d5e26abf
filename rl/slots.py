"""A sandbox child's slots in the machine's policy server: shared memory its cars' observations
are written to and their actions read from, and the socket that rings for them.

The policy server (``rl.policy_server``) gives each sandbox child a memory file of its own (a
``memfd``, mapped by both) and one end of a socket pair. A step of the child's cars is one round
trip: the child writes the request (how to act, the cars' seeds, one observation row a car) into
its slots and sends ``ASK``; the server copies the rows out, checks them, runs one batched forward
pass for every child driving with the same policy, writes each car's action (with PPO's value
and log-probability) back into the child's slots and answers ``ANSWERED``, or ``REFUSED`` and a
reason before it closes the child's socket. A child sees only its own slots: the file and the
socket are the only things of the server it is given.

The layout is fixed when the slots are opened, from the policy's spaces (``Layout``), and both
sides place the same arrays at the same offsets. The child's side (``SlotClient``) imports no
torch: a child whose policy is served never loads it.
"""

from __future__ import annotations

import mmap
import os
import select
from dataclasses import dataclass
from math import prod

import numpy as np

ASK = b"?"
ANSWERED = b"!"
REFUSED = b"x"  # followed by the reason, in words
HOW = ("explore", "drive", "value")
HEADER_FIELDS = 2  # how (an index into HOW), the rows asked for; the rows' seeds follow
ALIGN = 64  # [bytes] each array starts on a cache line


class SlotsFailed(Exception):
    """The policy server did not answer the child's cars: it refused them (the reason given),
    went away, or took longer than the child's patience."""


@dataclass(frozen=True)
class Layout:
    """Where each array lies in a child's slots: the observations' names, shapes and dtypes,
    the action's shape and dtype, and the cars (rows) there are."""

    observations: tuple[tuple[str, tuple[int, ...], str], ...]
    action: tuple[tuple[int, ...], str]
    cars: int

    @classmethod
    def of(cls, observation_space, action_space, cars: int) -> Layout:
        """The layout for a policy of these Gymnasium spaces driving ``cars`` cars."""
        observations = tuple(
            (name, tuple(space.shape), str(space.dtype))
            for name, space in observation_space.spaces.items()
        )
        discrete = hasattr(action_space, "n")
        action = ((), "int64") if discrete else (tuple(action_space.shape), "float32")
        return cls(observations, action, cars)

    @classmethod
    def from_message(cls, message: dict) -> Layout:
        return cls(
            tuple((name, tuple(shape), dtype) for name, shape, dtype in message["observations"]),
            (tuple(message["action"][0]), message["action"][1]),
            int(message["cars"]),
        )

    def message(self) -> dict:
        return {
            "observations": [[name, list(shape), kind] for name, shape, kind in self.observations],
            "action": [list(self.action[0]), self.action[1]],
            "cars": self.cars,
        }

    def arrays(self) -> list[tuple[str, tuple[int, ...], str]]:
        """Every array of the slots, in order: the header, each observation's rows, the
        actions, values and log-probabilities."""
        rows = self.cars
        return [
            ("header", (HEADER_FIELDS + rows,), "int64"),
            *((f"obs:{name}", (rows, *shape), kind) for name, shape, kind in self.observations),
            ("actions", (self.cars, *self.action[0]), self.action[1]),
            ("values", (self.cars,), "float32"),
            ("log_probs", (self.cars,), "float32"),
        ]

    @property
    def size(self) -> int:
        """[bytes] of the slots."""
        return sum(
            _aligned(prod(shape) * np.dtype(kind).itemsize) for _, shape, kind in self.arrays()
        )

    def views(self, buffer) -> dict[str, np.ndarray]:
        """Each array of the slots, a view into ``buffer`` (the mapped file)."""
        views, offset = {}, 0
        for name, shape, dtype in self.arrays():
            views[name] = np.ndarray(shape, np.dtype(dtype), buffer=buffer, offset=offset)
            offset += _aligned(prod(shape) * np.dtype(dtype).itemsize)
        return views


def _aligned(size: int) -> int:
    return -(-size // ALIGN) * ALIGN


def mapped(fd: int, size: int) -> mmap.mmap:
    """The slots' file ``fd``, mapped shared, read and written."""
    return mmap.mmap(fd, size, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)


class SlotClient:
    """The child's side: its cars' rows written into the slots, the server rung, the answer
    read, within ``patience`` seconds a step."""

    def __init__(self, layout: Layout, memory_fd: int, socket_fd: int, patience: float) -> None:
        self.layout, self.socket_fd, self.patience = layout, socket_fd, patience
        self.memory = mapped(memory_fd, layout.size)
        os.close(memory_fd)  # the mapping holds the file
        self.views = layout.views(self.memory)
        self.ready = select.poll()
        self.ready.register(socket_fd, select.POLLIN)

    def act(self, how: str, observations: list[dict], seeds: list[int] | None) -> dict:
        """The server's arrays for ``observations`` (one a car; ``seeds``, the cars' own, for
        "explore"): the actions and, for PPO, the values and log-probabilities, row by row;
        "value" answers the values alone."""
        rows = len(observations)
        header = self.views["header"]
        header[0], header[1] = HOW.index(how), rows
        header[HEADER_FIELDS : HEADER_FIELDS + rows] = seeds if seeds is not None else 0
        for name, _, _ in self.layout.observations:
            slots = self.views[f"obs:{name}"]
            for row, observation in enumerate(observations):
                slots[row] = observation[name]
        try:
            os.write(self.socket_fd, ASK)
            if not self.ready.poll(int(self.patience * 1000)):
                raise SlotsFailed(f"The policy server gave no answer in {self.patience:g} s.")
            answer = os.read(self.socket_fd, 4096)
        except OSError:
            answer = b""
        if answer != ANSWERED:
            reason = answer[1:].decode("utf-8", "replace") if answer[:1] == REFUSED else ""
            raise SlotsFailed(reason or "The policy server went away.")
        return {name: self.views[name][:rows].copy() for name in ("actions", "values", "log_probs")}
