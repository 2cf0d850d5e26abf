"""The zygote: ``python -s -m sandbox.zygote FD``, a clean interpreter, one per worker process, that
has loaded a sandbox child's code once and forks every child from there (``spawner.Zygote``).

A child started as a fresh interpreter imports numpy, OpenCV and the simulator, then forks its
reward process, which imports the libraries a racer's code may use (SciPy and Shapely above all,
``reward.PRELOADED``): about 0.7 s of CPU at every reward check and every rollout, most of a
reward check's cost. The zygote is started as such a child was (the children's empty
environment, a session of its own), imports all of that and does nothing else: it holds no
secret, starts no thread and never runs a racer's code. For each request on its socket (FD) it
forks a child, which takes the pipes the worker sent as its standard ones (and the policy
server's slots at the numbers the worker gave them), closes every other descriptor, leaves for a
session of its own at the niceness asked, draws fresh random seeds and runs ``sandbox.child``:
from there it is the process a fresh interpreter would be, and seals itself the same way.

The zygote reaps its children and writes each one's wait status on the pipe the worker sent for
it. It exits when its socket closes (its worker has gone, however it went), and its children
with it: each dies with its parent (``seal.die_with``). This module never imports Django.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import select
import socket
import sys
import traceback

from sandbox.spawner import MAX_PASSED, STATUS


def main() -> None:
    control = socket.socket(fileno=int(sys.argv[1]))
    _load()
    # A fork copies one thread: a lock another held would stay locked in every child.
    threads = len(os.listdir("/proc/self/task"))
    if threads != 1:
        sys.exit(f"the sandbox's zygote has {threads} threads after its imports; it forks none")
    control.send(b"ready")
    children: dict[int, tuple[int, int]] = {}  # pidfd: the child's pid, its status pipe
    ready = select.poll()
    ready.register(control, select.POLLIN)
    while True:
        for fd, _ in ready.poll():
            if fd != control.fileno():
                _reap(fd, *children.pop(fd))
                ready.unregister(fd)
                continue
            try:
                request, fds, _, _ = socket.recv_fds(control, 4096, MAX_PASSED)
            except OSError:
                request, fds = b"", []
            if not request:  # the worker has gone: so do we, and the children with us
                os._exit(0)
            try:
                pid, pidfd = _fork(json.loads(request), fds[1:])
            except Exception as error:  # a request we cannot serve: the worker says so
                for received in fds:
                    os.close(received)
                control.send(json.dumps({"error": str(error)[:200]}).encode())
                continue
            try:
                socket.send_fds(control, [json.dumps({"pid": pid}).encode()], [pidfd])
            except OSError:  # the worker went while we forked
                os._exit(0)
            children[pidfd] = (pid, fds[0])
            ready.register(pidfd, select.POLLIN)


def _load() -> None:
    """Import what every child and its reward process would: the children start with it. (The
    seal's pyseccomp; never torch, which only a child that holds its policy loads.)"""
    import importlib

    from sandbox.reward import PRELOADED

    for name in ("pyseccomp", "sandbox.child", "simulator.env", "simulator.samples", *PRELOADED):
        importlib.import_module(name)


def _fork(request: dict, given: list[int]) -> tuple[int, int]:
    targets = [int(target) for target in request["targets"]]
    if len(targets) != len(given):
        raise ValueError(f"{len(given)} descriptors sent for {len(targets)} places")
    pid = os.fork()
    if pid == 0:
        try:
            _become_child(given, targets, int(request["niceness"]))
        except BaseException:  # before the child's own code: say it on its standard error
            traceback.print_exc(file=sys.stderr)
        finally:
            os._exit(70)
    for fd in given:
        os.close(fd)
    return pid, os.pidfd_open(pid)


def _become_child(given: list[int], targets: list[int], niceness: int) -> None:
    """In the forked child: take the worker's descriptors at their places, close all else, and
    run ``sandbox.child`` as a fresh interpreter would."""
    os.setsid()
    os.setpriority(os.PRIO_PROCESS, 0, max(niceness, os.getpriority(os.PRIO_PROCESS, 0)))
    above = max([*targets, *given]) + 1
    moved = [fcntl.fcntl(fd, fcntl.F_DUPFD, above) for fd in given]
    for fd, target in zip(moved, targets, strict=True):
        os.dup2(fd, target)
    low = 0
    for kept in sorted(set(targets)):
        if low < kept:  # closerange(0, 0) would close everything
            os.closerange(low, kept)
        low = kept + 1
    os.closerange(low, os.sysconf("SC_OPEN_MAX"))
    import numpy

    # A fresh interpreter's seeds, not the zygote's, for the racer's code (``random`` draws its
    # own at a fork).
    numpy.random.seed()

    from sandbox import child

    child.main()


def _reap(pidfd: int, pid: int, status_pipe: int) -> None:
    """Reap a child that ended and tell its worker how."""
    _, status = os.waitpid(pid, 0)
    with contextlib.suppress(OSError):  # the worker has stopped listening
        os.write(status_pipe, STATUS.pack(status))
    os.close(status_pipe)
    os.close(pidfd)


if __name__ == "__main__":
    main()
