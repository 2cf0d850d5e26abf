"""A rollout worker's side of the machine's policy server (``rl.policy_server``): a sandbox
child's slots, opened for the child and handed to it, and the weights it drives with.

The first worker on a machine to need the server starts it (under a file lock, so two workers
never start two), and every worker after connects to it; it ends itself once no worker has
needed it for a while. This module imports no torch: the worker that holds a lease never runs
the policy.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from rl.slots import Layout
from rl.wire import ProtocolError, receive_message, send_message

START_PATIENCE = 90.0  # [s] for a server just started to listen (it imports PyTorch)
ANSWER_PATIENCE = 120.0  # [s] for its answer to a worker (a new policy built on a cold GPU)
ROOT = Path(__file__).resolve().parent.parent


class PolicyServerFailed(Exception):
    """The machine's policy server could not be started or reached, or refused; in words."""


class PolicyLease:
    """A sandbox child's slots in the machine's policy server at ``path``: open them
    (``open``), hand ``child_settings`` and ``fds`` to the child as it starts, then ``handed``
    (the worker's copies closed, so the server sees the child go when it does); give the
    weights with ``weights``; ``close`` lets the slots go."""

    def __init__(self, path: str | os.PathLike, device: str = "auto") -> None:
        self.path, self.device = str(path), device
        self.connection: socket.socket | None = None
        self.layout: Layout | None = None
        self.served_on = ""  # the server's device, as it said
        self.server_pid = 0
        self.fds: tuple[int, ...] = ()

    def open(self, *, job: int, algorithm: str, architecture: str, env: dict, seed: int, cars: int):
        self.connection = connect(self.path, self.device)
        answer, fds = self._ask(
            {
                "op": "open",
                "job": job,
                "algorithm": algorithm,
                "architecture": architecture,
                "env": env,
                "seed": seed,
                "cars": cars,
            }
        )
        if answer.get("type") != "opened" or len(fds) != 2:
            for fd in fds:
                os.close(fd)
            raise PolicyServerFailed(f"The policy server opened no slots: {_words(answer)}")
        self.layout, self.served_on = Layout.from_message(answer["layout"]), answer["device"]
        self.server_pid = int(answer["pid"])
        self.fds = tuple(fds)

    def child_settings(self, patience: float) -> dict:
        """What the child is told of its slots: their layout and its descriptors."""
        memory, ring = self.fds
        return {
            "layout": self.layout.message(),
            "memory_fd": memory,
            "socket_fd": ring,
            "patience": patience,
        }

    def handed(self) -> None:
        """The child has its descriptors: this process's copies are closed."""
        for fd in self.fds:
            os.close(fd)
        self.fds = ()

    def weights(self, data: bytes) -> None:
        """The child drives with ``data`` (weights as the trainer publishes them) from its next
        step: sent to the server only where no worker on the machine has sent them."""
        digest = hashlib.sha256(data).hexdigest()
        answer, _ = self._ask({"op": "weights", "digest": digest})
        if answer.get("type") == "weights" and not answer.get("have"):
            answer, _ = self._ask({"op": "weights_data", "data": data})
        if answer.get("type") != "weights" or not answer.get("have"):
            raise PolicyServerFailed(f"The policy server took no weights: {_words(answer)}")

    def stats(self) -> dict:
        """The server's counts: its batched passes, the rows they ran, the most in one, and
        the policies it holds."""
        return self._ask({"op": "stats"})[0]

    def close(self) -> None:
        self.handed()
        if self.connection is not None:
            self.connection.close()
            self.connection = None

    def _ask(self, message: dict) -> tuple[dict, list[int]]:
        try:
            send_message(self.connection, message)
            answer, fds = receive_message(self.connection)
        except (OSError, ProtocolError) as error:
            raise PolicyServerFailed(f"The policy server went away ({error}).") from None
        if answer is None:
            raise PolicyServerFailed("The policy server went away.")
        return answer, fds


def _words(answer: dict) -> str:
    return str(answer.get("message") or f"it answered {answer.get('type')!r}")[:300]


def connect(path: str, device: str) -> socket.socket:
    """A connection to the machine's policy server at ``path``, started first where none
    listens (the first worker to find none starts it; the others wait for it on the lock)."""
    with contextlib.suppress(OSError):
        return _connected(path)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(f"{path}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        with contextlib.suppress(OSError):
            return _connected(path)
        return _started(path, device)


def _connected(path: str) -> socket.socket:
    connection = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        connection.settimeout(ANSWER_PATIENCE)
        connection.connect(path)
    except OSError:
        connection.close()
        raise
    return connection


def _started(path: str, device: str) -> socket.socket:
    if len(os.fsencode(path)) > 107:
        raise PolicyServerFailed(
            f"The policy server's socket path is too long for the system ({path}): set "
            "PITLANE_POLICY_SOCKET to a shorter one."
        )
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)  # a dead server's
    with open(f"{path}.log", "ab") as log:  # the server keeps its own copy open
        before = log.tell()
        server = subprocess.Popen(
            [sys.executable, "-m", "rl.policy_server", "--socket", path, "--device", device],
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=log,
            start_new_session=True,  # it serves the machine: it outlives the worker that started it
        )
    deadline = time.monotonic() + START_PATIENCE
    while time.monotonic() < deadline:
        if server.poll() is not None:
            said = Path(f"{path}.log").read_bytes()[before:][-400:]
            words = said.decode("utf-8", "replace").strip() or f"it exited with {server.returncode}"
            raise PolicyServerFailed(f"The policy server did not start: {words}")
        with contextlib.suppress(OSError):
            return _connected(path)
        time.sleep(0.05)
    server.kill()
    raise PolicyServerFailed(f"The policy server did not listen within {START_PATIENCE:g} s.")
