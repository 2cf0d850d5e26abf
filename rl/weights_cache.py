"""A machine's copy of the policy weights its rollout workers drive with, so that Redis sends each
iteration's weights (46.7 MB for the 3-layer PPO) once per machine rather than once per worker.

The first worker on a machine to need a version takes the job's file lock, fetches the weights
from Redis and writes them to a temporary file that it then renames into place (``os.replace``:
a reader sees the whole file or none); the others wait on the lock for that one fetch and read
the file. A file is named by what the trainer published with the weights: the version, their
size and their SHA-256 (``<version>-<size>-<sha256>.weights``), and every read checks the size
and the hash, so a torn file (a machine that crashed before the page cache reached the disk) or
a stale one (a run restarted from an earlier checkpoint publishes the same version with other
weights) is never loaded: it is removed and fetched again. Disk use is bounded: a job keeps only
its newest version, a temporary file left by a worker that died writing is removed under the
lock, and a job none of whose workers stored a version for ``IDLE_JOB`` (ended, or its workers
gone) is removed by the next store of any job. Whatever goes wrong with the files (no room, no
permission, a lock held too long) costs only the cache: the weights come from Redis as before.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import logging
import os
import secrets
import shutil
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

logger = logging.getLogger(__name__)

IDLE_JOB = (
    3600  # [s] a job's files stored no version this long are removed (Redis's keys expire so)
)
LOCK_PATIENCE = 60.0  # [s] a worker waits this long for another's fetch, then fetches itself
LOCK_POLL = 0.005  # [s] between tries of the lock
SUFFIX = ".weights"
TEMPORARY = ".writing-"
LOCK = ".lock"


def weights_digest(weights: bytes) -> str:
    """The hash a published version carries (SHA-256: 45 ms for 46.7 MB on a dev-box core)."""
    return hashlib.sha256(weights).hexdigest()


@dataclass(frozen=True)
class Published:
    """What the trainer published beside the weights: enough to name and check them."""

    version: int
    size: int  # [bytes]
    digest: str  # ``weights_digest``

    @property
    def file_name(self) -> str:
        return f"{self.version}-{self.size}-{self.digest}{SUFFIX}"


Fetch = Callable[[], tuple[Published, bytes]]  # the newest weights, from Redis


class WeightsCache:
    """The weights of the jobs this machine's workers drive, under ``directory``: a folder a job."""

    def __init__(
        self, directory: Path | str, *, idle_job: float = IDLE_JOB, patience: float = LOCK_PATIENCE
    ) -> None:
        self.directory = Path(directory)
        self.idle_job = idle_job
        self.patience = patience

    def weights(self, job_id: int, published: Published, fetch: Fetch) -> tuple[int, bytes]:
        """The weights of ``published``, or newer ones where ``fetch`` finds the trainer published
        again meanwhile: (version, weights), read from this machine's file where there is one,
        else fetched once for the machine."""
        folder = self.directory / f"job-{job_id}"
        found = self._read(folder / published.file_name, published)
        if found is not None:
            return published.version, found
        try:
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)
            lock = open(folder / LOCK, "a+b")  # noqa: SIM115 (closed by the block below)
        except OSError as error:
            logger.warning("The weights cache %s is unusable (%s); fetching", self.directory, error)
            fresh, weights = fetch()
            return fresh.version, weights
        with lock, self._locked(lock, folder) as held:
            found = self._read(folder / published.file_name, published)  # another's fetch
            if found is not None:
                return published.version, found
            fresh, weights = fetch()
            if held:
                self._store(folder, fresh, weights)
        return fresh.version, weights

    def _read(self, path: Path, published: Published) -> bytes | None:
        try:
            data = path.read_bytes()
        except OSError:  # none yet, or pruned as it was read: fetched under the lock
            return None
        if len(data) == published.size and weights_digest(data) == published.digest:
            return data
        logger.warning("Removed a damaged copy of weights version %s: %s", published.version, path)
        path.unlink(missing_ok=True)
        return None

    @contextlib.contextmanager
    def _locked(self, lock: BinaryIO, folder: Path) -> Iterator[bool]:
        """The job's lock (the open ``lock`` file), held for the block; False when another held
        it past ``patience`` (the block then fetches without storing). ``flock`` ends with its
        holder's process, however that ends."""
        deadline = time.monotonic() + self.patience
        while True:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    logger.warning(
                        "Waited %.0f s for the lock of %s; fetching", self.patience, folder
                    )
                    yield False
                    return
                time.sleep(LOCK_POLL)
        try:
            yield True
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)

    def _store(self, folder: Path, published: Published, weights: bytes) -> None:
        """Under the job's lock: the job's one file becomes ``published``'s; other jobs idle past
        ``idle_job`` are removed."""
        try:
            for old in folder.iterdir():  # older versions, and what a writer that died left
                if old.name != LOCK and old.name != published.file_name:
                    old.unlink(missing_ok=True)
            temporary = folder / f"{TEMPORARY}{os.getpid()}-{secrets.token_hex(4)}"
            try:
                temporary.write_bytes(weights)
                os.replace(temporary, folder / published.file_name)
            finally:
                temporary.unlink(missing_ok=True)
        except OSError as error:
            level = logging.WARNING if error.errno == errno.ENOSPC else logging.INFO
            logger.log(level, "Weights version %s not cached: %s", published.version, error)
            return
        self._prune(keep=folder)

    def _prune(self, keep: Path) -> None:
        idle_since = time.time() - self.idle_job
        with contextlib.suppress(OSError):
            for folder in self.directory.iterdir():
                if folder != keep and folder.name.startswith("job-"):
                    with contextlib.suppress(OSError):
                        if folder.stat().st_mtime < idle_since:
                            shutil.rmtree(folder, ignore_errors=True)
