"""var/ as another user of the machine meets it: an install from before issue 55 (readable by
everyone), and reads tried for real, by a child process that drops root for ``nobody``."""

from __future__ import annotations

import errno
import json
import os
import stat
from collections.abc import Callable
from pathlib import Path

import pytest

NOBODY = 65534  # Debian's nobody and nogroup


EARLIER_FILES = ("db.sqlite3", "db.sqlite3-wal", "redis/dump.rdb", "media/models/1/best.pt")


def an_install_from_before(var: Path, names: tuple[str, ...] = EARLIER_FILES) -> None:
    """var/ as `make run` left it before issue 55, with ``names`` in it (their contents made
    up): everything readable by everyone."""
    for name in names:
        (var / name).parent.mkdir(parents=True, exist_ok=True)
        (var / name).write_bytes(b"sessions and weights")
    for path in (var, *var.rglob("*")):
        path.chmod(0o755 if path.is_dir() else 0o644)


def read_as_another_user(root: Path, paths: list[str]) -> dict[str, str]:
    """What user ``nobody`` gets reading each of ``paths`` (relative to ``root``; "." is
    ``root`` itself, listed): "read", or the error's name ("EACCES"). ``nobody`` reaches
    ``root`` as if the folders above it let everyone through, as an install's parents do
    (a home folder, /srv), though the test's own temporary folders do not. Skipped unless the
    suite runs as root: only root can become another user."""
    reads = as_nobody(root, lambda above: json.dumps({p: _read(above, p) for p in paths}).encode())
    return json.loads(reads)


def as_nobody(root: Path, work: Callable[[int], bytes]) -> bytes:
    """What ``work`` returns, run by a child process that has become user ``nobody``, given a
    descriptor of ``root`` (root's to open, nobody's to use). Skipped unless the suite runs as
    root: only root can become another user."""
    if os.geteuid() != 0:
        pytest.skip("Being another user than the files' owner needs the suite to run as root.")
    above = os.open(root, os.O_PATH | os.O_DIRECTORY)
    reader, writer = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: syscalls only, then out, whatever happens
        code = 1
        try:
            os.close(reader)
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            os.write(writer, work(above))
            code = 0
        finally:
            os._exit(code)
    os.close(writer)
    with os.fdopen(reader, "rb") as answer:
        results = answer.read()
    os.close(above)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, "the child that became nobody failed"
    return results


def _read(above: int, path: str) -> str:
    try:
        descriptor = os.open(path, os.O_RDONLY, dir_fd=above)
    except OSError as error:
        return errno.errorcode[error.errno]
    try:
        if stat.S_ISDIR(os.fstat(descriptor).st_mode):
            os.listdir(descriptor)
        else:
            os.read(descriptor, 1)
        return "read"
    except OSError as error:
        return errno.errorcode[error.errno]
    finally:
        os.close(descriptor)
