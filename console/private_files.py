"""The data directory (var/) is its owner's alone: no other user of the machine reads or lists it.

It holds the sessions (the database, with its WAL and shared-memory files), Redis's dump, log and
append-only file, racers' models and uploads, the secret key: a local user who could read them
could sign in as anyone, staff included. So the processes ``make run`` starts (the supervisor,
Redis, the workers, the web server) create files with the umask 077 (files 0600, folders 0700),
Django stores uploads and their folders so too (``FILE_UPLOAD_PERMISSIONS``), and every start
takes the group's and others' permissions off whatever var/ already holds (an install from before
this, a file copied in by hand).

Uploads in progress are spooled to ``FILE_UPLOAD_TEMP_DIR``, a folder under var/ too: a web
server killed during an upload leaves its file there, and the workers' housekeeping deletes what
nothing has written to for ``STALE_UPLOAD`` (``temporary_uploads_sweep``).
"""

from __future__ import annotations

import logging
import os
import stat
import time
from pathlib import Path

logger = logging.getLogger(__name__)

PRIVATE_UMASK = 0o077  # files 0600, folders 0700
STALE_UPLOAD = 3600  # [s] a temporary upload unwritten this long is its dead request's: an
# upload's file is written as each chunk arrives, and the longest work on one after it has all
# arrived (an import's checks, its weights stored) takes minutes


def files_private() -> None:
    """Create every file of this process, and of the processes it starts, for its owner only."""
    os.umask(PRIVATE_UMASK)


def private_dir(path: Path) -> Path:
    """``path``, a folder created for its owner only (0700) where there is none."""
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    return path


def data_dir_private(var_dir: Path) -> int:
    """Take the group's and others' permissions off ``var_dir`` and everything under it (the
    owner's stay: 0755 becomes 0700, 0644 0600); how many it changed. Symbolic links are neither
    followed nor changed: what one points to outside var/ is not var/'s."""
    changed = 0
    for folder, folders, files in os.walk(var_dir, followlinks=False):
        for name in (".", *folders, *files):
            changed += _private(os.path.join(folder, name))
    return changed


def _private(path: str) -> int:
    """1 where ``path``'s mode was changed. It is opened without following a link (one swapped in
    after os.walk saw a file is refused) and changed through that descriptor; a file deleted
    meanwhile, or another user's (left by a ``sudo make run``), is logged and left, never a
    traceback that stops the console's start."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_NOCTTY)
    except FileNotFoundError:  # deleted meanwhile by a process of the console
        return 0
    except OSError as error:  # a link (ELOOP), a socket, or not ours to open
        if not os.path.islink(path):
            logger.warning("var/: %s could not be opened to make it private: %s", path, error)
        return 0
    try:
        status = os.fstat(descriptor)
        if not (stat.S_ISDIR(status.st_mode) or stat.S_ISREG(status.st_mode)):
            return 0  # a FIFO, a device
        mode = stat.S_IMODE(status.st_mode)
        if not mode & 0o077:
            return 0
        os.fchmod(descriptor, mode & 0o700)
        return 1
    except PermissionError:
        logger.warning(
            "var/: %s belongs to uid %s, not this user: others may still read it; remove it or "
            "chown it to this user",
            path,
            os.fstat(descriptor).st_uid,
        )
        return 0
    finally:
        os.close(descriptor)


def temporary_uploads_sweep(folder: Path, *, older_than: float = STALE_UPLOAD) -> list[str]:
    """Delete the files in ``folder`` (``FILE_UPLOAD_TEMP_DIR``) that nothing has written to
    for ``older_than`` seconds: uploads whose web server was killed before it could. What was
    deleted, in words for the log."""
    deleted = []
    oldest = time.time() - older_than
    try:
        entries = list(os.scandir(folder))
    except FileNotFoundError:
        return []
    for entry in entries:
        try:
            if entry.is_file(follow_symlinks=False) and entry.stat().st_mtime < oldest:
                size = entry.stat().st_size
                os.unlink(entry.path)
                deleted.append(
                    f"temporary upload {entry.name} ({size:,} bytes) was left by a stopped web "
                    "server; it was deleted"
                )
        except FileNotFoundError:  # its request ended meanwhile, and deleted it
            continue
    return deleted
