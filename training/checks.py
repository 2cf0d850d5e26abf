"""Racers' code and archives are checked off the request thread, in a bounded pool.

Validating a reward function runs it in the sandbox on sample situations (1.5 to 3 CPU-seconds
and up to ``rewards.SAMPLE_TIMEOUT`` per sample); importing a model reads an untrusted archive,
loads its weights into a network and validates its reward function. Views that do either are
``async``: they hand the work to this module's pool of ``PITLANE_CHECKERS`` threads and await it,
so while a check runs the web server holds a coroutine, not one of the few threads that serve
every other page. At most ``PITLANE_CHECKS_WAITING`` more checks wait for a checker; past that a
racer is told at once to try again (``Busy``), rather than queueing without end behind a flood.

A check's thread waits on the sandbox's pipes; the racer's code itself runs in the sandbox's
processes, under their own limits (``sandbox``). A check keeps running to its end when
its racer leaves, which those limits bound.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

from django.conf import settings
from django.db import close_old_connections

T = TypeVar("T")

RETRY_AFTER = 5  # [s] what a racer turned away is asked to wait


class Busy(Exception):
    """Every checker is busy and the waiting line is full."""

    def __init__(self) -> None:
        super().__init__(
            "Every checker is busy with other racers' code right now: try again in a few seconds."
        )


class _Pool:
    def __init__(self, checkers: int, waiting: int) -> None:
        self.checkers, self.waiting = checkers, waiting
        self.executor = ThreadPoolExecutor(max_workers=checkers, thread_name_prefix="checker")
        self.admitted = threading.BoundedSemaphore(checkers + waiting)

    def submit(self, work: Callable[[], T]) -> Future[T]:
        if not self.admitted.acquire(blocking=False):
            raise Busy()
        try:
            future = self.executor.submit(_in_checker, work)
        except BaseException:
            self.admitted.release()
            raise
        # A place is given back when the work ends (or is cancelled before it starts), not when
        # the racer stops waiting: racers who leave cannot pile work up behind the checkers.
        future.add_done_callback(lambda _: self.admitted.release())
        return future


def _in_checker(work: Callable[[], T]) -> T:
    """``work`` on a checker's thread, which keeps a database connection of its own between
    checks; as around a request, one that is too old or broken is closed before and after."""
    close_old_connections()
    try:
        return work()
    finally:
        close_old_connections()


_pool: _Pool | None = None
_pool_lock = threading.Lock()


def pool() -> _Pool:
    """This process's pool, made on first use with the settings' sizes."""
    global _pool
    with _pool_lock:
        size = (settings.PITLANE_CHECKERS, settings.PITLANE_CHECKS_WAITING)
        if _pool is None or (_pool.checkers, _pool.waiting) != size:  # settings changed: tests
            if _pool is not None:
                _pool.executor.shutdown(wait=False)
            _pool = _Pool(*size)
        return _pool


async def run(work: Callable[[], T]) -> T:
    """``work()``'s result (or its exception), computed by a checker; ``Busy`` at once when
    every checker is taken and the waiting line is full. Cancelling the await cancels the work
    only if it has not started."""
    return await asyncio.wrap_future(pool().submit(work))
