"""A worker's side of its zygote (``sandbox.zygote``): ``Zygote.spawn`` gives a sandbox child
forked there as ``Spawned``, which ``Sandbox`` drives as it would a ``subprocess.Popen``.

A worker cannot wait for a process it did not fork, so the zygote reaps its children and writes
each one's wait status on a pipe the worker sent with the request; the worker kills a child
through its pidfd, which names that process and no other even once its number is reused. One
zygote serves a process's threads; a forked process (a Celery pool's) starts its own, and closes
its copy of its parent's socket, so that a zygote still ends when its own worker goes.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATUS = struct.Struct("i")
MAX_PASSED = 16  # descriptors a request may carry: the status pipe, three pipes, the slots
START_TIMEOUT = 120.0  # [s] for the zygote to load the children's code, on a busy machine
FORK_TIMEOUT = 30.0  # [s] for it to answer a request


class ZygoteFailed(Exception):
    """The zygote could not be started or did not answer; says which, for the log."""


class Spawned:
    """A child the zygote forked, with the parts of ``subprocess.Popen`` that ``Sandbox`` uses:
    its pipes, ``pid``, ``poll``, ``wait``, ``kill`` and ``returncode``."""

    def __init__(self, pid: int, pidfd: int, status: int, stdin: int, stdout: int, stderr: int):
        self.pid = pid
        self.returncode: int | None = None
        self.stdin = os.fdopen(stdin, "wb", buffering=0)
        self.stdout = os.fdopen(stdout, "rb")
        self.stderr = os.fdopen(stderr, "rb", buffering=0)
        self._pidfd, self._status = pidfd, status
        self._lock = threading.Lock()

    def poll(self) -> int | None:
        return self._ended(0.0)

    def wait(self, timeout: float | None = None) -> int:
        code = self._ended(timeout)
        if code is None:
            raise subprocess.TimeoutExpired("sandbox.child", timeout or 0.0)
        return code

    def kill(self) -> None:
        with self._lock:
            if self.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    signal.pidfd_send_signal(self._pidfd, signal.SIGKILL)

    def __del__(self) -> None:
        # Never waited for (a worker that stopped holding it): its two descriptors still go.
        if self.returncode is None:
            for fd in (self._status, self._pidfd):
                with contextlib.suppress(OSError):
                    os.close(fd)

    def _ended(self, timeout: float | None) -> int | None:
        """The exit code once the zygote has reaped the child (as Popen gives it: minus the
        signal that killed it); None if it has not within ``timeout`` seconds."""
        if self.returncode is None and select.select([self._status], [], [], timeout)[0]:
            with self._lock:
                if self.returncode is None:
                    data = os.read(self._status, STATUS.size)
                    # Nothing written: the zygote went first, and the child with it (SIGKILL).
                    status = STATUS.unpack(data)[0] if len(data) == STATUS.size else signal.SIGKILL
                    self.returncode = os.waitstatus_to_exitcode(status)
                    os.close(self._status)
                    os.close(self._pidfd)
        return self.returncode


class Zygote:
    """This process's handle on its zygote, started at the first ``spawn`` (and again after a
    fork, or once it has died); shared by the process's threads."""

    def __init__(self, environment: dict[str, str]) -> None:
        self.environment = environment  # the zygote's and so its children's: nothing of ours
        self._lock = threading.Lock()
        self._process: subprocess.Popen | None = None
        self._socket: socket.socket | None = None
        self._owner = 0  # the pid of the process that started it
        os.register_at_fork(after_in_child=self._after_fork)
        atexit.register(self.stop)

    def spawn(self, *, pass_fds: tuple[int, ...] = (), niceness: int = 0) -> Spawned:
        """A sandbox child, with ``pass_fds`` at the same numbers, at ``niceness`` (absolute,
        never below the zygote's own); ``ZygoteFailed`` if no zygote answers."""
        stdin, stdin_ours = os.pipe()
        stdout_ours, stdout = os.pipe()
        stderr_ours, stderr = os.pipe()
        status_ours, status = os.pipe()
        request = json.dumps({"targets": [0, 1, 2, *pass_fds], "niceness": niceness})
        try:
            with self._lock:
                pid, pidfd = self._ask(request.encode(), [status, stdin, stdout, stderr, *pass_fds])
        except BaseException:
            for fd in (stdin_ours, stdout_ours, stderr_ours, status_ours):
                os.close(fd)
            raise
        finally:
            for fd in (stdin, stdout, stderr, status):
                os.close(fd)
        return Spawned(pid, pidfd, status_ours, stdin_ours, stdout_ours, stderr_ours)

    def stop(self) -> None:
        """Close the socket, which ends the zygote and any child still running."""
        with self._lock:
            if self._socket is not None and self._owner == os.getpid():
                self._socket.close()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self._process.wait(5.0)
            self._forget()

    def _ask(self, request: bytes, fds: list[int]) -> tuple[int, int]:
        if self._owner != os.getpid() or self._process.poll() is not None:
            self._start()
        try:
            socket.send_fds(self._socket, [request], fds)
            reply, received, _, _ = socket.recv_fds(self._socket, 4096, 1)
        except OSError as error:  # timed out, or the zygote went: the next spawn starts one
            self._kill()
            raise ZygoteFailed(f"the sandbox's zygote did not answer: {error}") from None
        answer = json.loads(reply or b"{}")
        if "pid" not in answer or len(received) != 1:
            for fd in received:
                os.close(fd)
            raise ZygoteFailed(f"the sandbox's zygote could not fork: {answer.get('error')}")
        return int(answer["pid"]), received[0]

    def _start(self) -> None:
        self._kill()
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        with theirs:
            try:
                self._process = subprocess.Popen(
                    [sys.executable, "-s", "-m", "sandbox.zygote", str(theirs.fileno())],
                    cwd=ROOT,
                    env=self.environment,
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    pass_fds=(theirs.fileno(),),
                    start_new_session=True,
                )
            except OSError as error:
                ours.close()
                raise ZygoteFailed(f"the sandbox's zygote could not be started: {error}") from None
        self._socket, self._owner = ours, os.getpid()
        ours.settimeout(START_TIMEOUT)
        try:
            ready = ours.recv(64)
        except OSError:
            ready = b""
        if ready != b"ready":
            self._kill()
            raise ZygoteFailed("the sandbox's zygote did not start (its error is in the log)")
        ours.settimeout(FORK_TIMEOUT)

    def _kill(self) -> None:
        if self._process is not None and self._owner == os.getpid():
            self._process.kill()
            self._process.wait()
        if self._socket is not None and self._owner == os.getpid():
            self._socket.close()
        self._forget()

    def _after_fork(self) -> None:
        self._lock = threading.Lock()  # held, perhaps, by a thread the fork left behind
        self._forget()

    def _forget(self) -> None:
        """Drop the handle. In a forked process the zygote is the parent's: the copy of its
        socket the fork made is closed, so that the zygote still ends when the parent goes."""
        if self._socket is not None and self._owner != os.getpid():
            self._socket.close()
        self._process, self._socket, self._owner = None, None, 0
