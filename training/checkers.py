"""Racers' code and archives are checked off the request thread, in a bounded pool shared fairly.

Validating a reward function runs it in the sandbox on sample situations (1.5 to 3 CPU-seconds
and up to ``rewards.SAMPLE_TIMEOUT`` per sample); importing a model reads an untrusted archive,
loads its weights into a network and validates its reward function. Views that do either are
``async``: they hand the work to this module's pool of ``PITLANE_CHECKERS`` threads and await it,
so while a check runs the web server holds a coroutine, not one of the few threads that serve
every other page. At most ``PITLANE_CHECKS_WAITING`` more checks wait for a checker; past that a
racer is told at once to try again (``Busy``), rather than queueing without end behind a flood.

The checkers are shared by racer, not by check, so that a few racers (or a few accounts of one)
sending check after check cannot keep the others out: a racer has at most ``RACER_PLACES``
checks in the pool, running or waiting (past that, ``Busy`` again, in words about their own
checks), and a free checker takes the next check of the racer who has the fewest running, and
among those of the one whose last check started longest ago; a racer with no check started in
the last ``SERVED_MEMORY`` seconds comes before all who had one (among them, who came first):
``common.turns``, the rule re-scorings take turns by too. A racer with nothing running is served
by the next free checker ahead of every flooder's waiting check (issue 55: a flooder whose check
ended before the bystander came went first before), and one racer holds a second checker only
while nobody else waits.

A check's thread waits on the sandbox's pipes; the racer's code itself runs in the sandbox's
processes, under their own limits (``sandbox``). A check keeps running to its end when
its racer leaves, which those limits bound.
"""

from __future__ import annotations

import asyncio
import itertools
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Hashable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import Any, TypeVar

from asgiref.sync import sync_to_async
from django.conf import settings
from django.db import close_old_connections
from django.http import HttpResponse

from common import turns
from sandbox import SandboxFailure, SandboxUnavailable
from simulator import tracks as simulator_tracks
from training import rewards

T = TypeVar("T")

RETRY_AFTER = 5  # [s] what a racer turned away is asked to wait
# A racer's checks in the pool at once, running or waiting: one running and the next one (a
# racer who validates, then saves, need not wait between the two); no more, so that a flood
# from a handful of accounts leaves the waiting line's other places to everyone else.
RACER_PLACES = 2
# [s] how long a racer's last check's start is remembered once they have nothing in the pool:
# one who checks again within it is still behind a racer who has not checked since.
SERVED_MEMORY = 600


class Busy(Exception):
    """Every checker is busy and the waiting line is full, or this racer's checks fill their
    own places (``RACER_PLACES``)."""

    def __init__(self, own: bool = False) -> None:
        super().__init__(
            "Your earlier checks are still running: try again in a few seconds, once they end."
            if own
            else "Every checker is busy with other racers' code right now: "
            "try again in a few seconds."
        )


class _Pool:
    """``checkers`` threads and a waiting line of ``waiting`` places, a queue per racer."""

    def __init__(self, checkers: int, waiting: int) -> None:
        self.checkers, self.waiting = checkers, waiting
        self.executor = ThreadPoolExecutor(max_workers=checkers, thread_name_prefix="checker")
        self._lock = threading.RLock()
        self._queues: dict[Hashable, deque[tuple[Future[Any], Callable[[], Any]]]] = {}
        self._placed: Counter[Hashable] = Counter()  # a racer's checks, running or waiting
        self._running: Counter[Hashable] = Counter()
        # When each racer's last check started (time.monotonic), kept SERVED_MEMORY seconds
        # after it: the least recently served waiting racer goes first, one never served (or
        # not lately) before all of them.
        self._served: dict[Hashable, float] = {}
        self._came: dict[Hashable, int] = {}  # the order racers with checks waiting came in
        self._ticks = itertools.count(1)
        self._free = checkers

    def submit(self, work: Callable[[], T], *, racer: Hashable) -> Future[T]:
        """``work``'s future, placed in ``racer``'s queue; ``Busy`` at once when there is no
        place for it."""
        future: Future[T] = Future()
        with self._lock:
            if sum(self._placed.values()) >= self.checkers + self.waiting:
                raise Busy()
            if self._placed[racer] >= RACER_PLACES:
                raise Busy(own=True)
            self._placed[racer] += 1
            self._came.setdefault(racer, next(self._ticks))
            self._queues.setdefault(racer, deque()).append((future, work))
            # A place is given back when the work ends, or when it is cancelled before it
            # starts, not when the racer stops waiting: racers who leave cannot pile work up.
            future.add_done_callback(lambda done: self._cancelled(racer, done))
            self._dispatch()
        return future

    def _dispatch(self) -> None:
        """Hand waiting checks to free checkers, fairest first (the module's docstring)."""
        while self._free and self._queues:
            racer = turns.next_racer(
                list(self._queues), running=self._running, served=self._served, came=self._came
            )
            queue = self._queues[racer]
            future, work = queue.popleft()
            if not queue:
                del self._queues[racer]
            self._free -= 1
            self._running[racer] += 1
            self._served[racer] = time.monotonic()
            self.executor.submit(self._check, racer, future, work)

    def _check(self, racer: Hashable, future: Future[Any], work: Callable[[], Any]) -> None:
        try:
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(_in_checker(work))
                except BaseException as error:  # the racer's to read, as the work's own result
                    future.set_exception(error)
        finally:
            with self._lock:
                self._free += 1
                self._running[racer] -= 1
                self._release(racer)
                self._dispatch()

    def _cancelled(self, racer: Hashable, future: Future[Any]) -> None:
        """A check cancelled while it waited leaves its racer's queue (a cancelled check that
        was already handed to a checker gives its place back there)."""
        if not future.cancelled():
            return
        with self._lock:
            queue = self._queues.get(racer, deque())
            for entry in queue:
                if entry[0] is future:
                    queue.remove(entry)
                    if not queue:
                        del self._queues[racer]
                    self._release(racer)
                    return

    def _release(self, racer: Hashable) -> None:
        self._placed[racer] -= 1
        for counts in (self._placed, self._running):
            if counts[racer] <= 0:
                del counts[racer]
        if racer not in self._placed:
            self._came.pop(racer, None)
            forgotten = time.monotonic() - SERVED_MEMORY
            for served in [r for r, at in self._served.items() if at < forgotten]:
                del self._served[served]


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


async def run(work: Callable[[], T], *, racer: Hashable) -> T:
    """``work()``'s result (or its exception), computed by a checker in ``racer``'s turn;
    ``Busy`` at once when there is no place for it. Cancelling the await cancels the work only
    if it has not started."""
    return await asyncio.wrap_future(pool().submit(work, racer=racer))


# A check that could not run: every checker busy, or the sandbox unable to start or to run it
FAILURES = (Busy, SandboxUnavailable, SandboxFailure)


async def reward_checked(
    source: str, track: str, *, racer: Hashable, direction: str = "counterclockwise"
) -> rewards.Validation | Exception:
    """``source`` validated on ``track`` (its name; an added track's route is read first) by a
    checker, in ``racer``'s turn; or why it could not be (one of ``FAILURES``), for the page or
    the API to say."""
    where = await sync_to_async(simulator_tracks.inline)(track)
    try:
        return await run(
            partial(rewards.reward_validate, source=source, track=where, direction=direction),
            racer=racer,
        )
    except FAILURES as error:
        return error


def failure_words(error: Exception) -> str:
    """What a racer reads when a check could not run (one of ``FAILURES``)."""
    if isinstance(error, Busy):
        return str(error)
    return f"The reward function could not be checked: {error}"


def failure_response(response: HttpResponse, error: Exception) -> HttpResponse:
    """``response`` for a check that could not run: 503, for the racer's input is not at fault,
    and when every checker was busy, when to try again."""
    response.status_code = 503
    if isinstance(error, Busy):
        response["Retry-After"] = str(RETRY_AFTER)
    return response
