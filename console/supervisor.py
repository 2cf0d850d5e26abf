"""What ``make run`` runs: a private Redis, the database set-up, a Celery worker per queue, Daphne.

Each queue has a worker of its own (``worker_pools``), as on several machines: the trainers, the
simulations (rollouts, evaluations, races) and the re-scorings each have their own processes, so
no job's trainer can take the place one of its rollouts needs (three trainers in one pool of three
processes waited for ever), and a re-scoring never holds an evaluation's. The trainers are as many
as the machine's memory holds (``console.sizing``); a job past them waits in the queue.

The supervisor starts each process in its own session, so Ctrl-C in the terminal reaches only the
supervisor, which then stops what it started in reverse order (web server, workers, Redis), each
with SIGTERM and, past a grace period, SIGKILL. Children are also asked by the kernel to stop should
the supervisor itself be killed. Once everything runs, a child that dies is started again, after a
pause that doubles with each death in a row (``RESTART_DELAYS``), and the output says so; only
Ctrl-C (or SIGTERM) stops the console. A lock file under var/ keeps a second supervisor from
starting over the first, and ports are checked before anything starts, so neither case ends in a
traceback.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import redis
from django.conf import settings
from django.core.management import call_command

from common.health import live_workers
from common.redis_client import redis_client
from console.env import _redact, env
from console.private_files import data_dir_private, files_private, private_dir
from console.sizing import Sizing

STOP_GRACE = 15.0  # [s] between SIGTERM and SIGKILL
START_TIMEOUT = 60.0  # [s] for Redis and the web server to answer
RESTART_DELAYS = (1.0, 2.0, 4.0, 8.0, 16.0, 30.0)  # [s] before a restart, by deaths in a row
STEADY = 60.0  # [s] a restarted child that runs this long has recovered: its next death waits 1 s
_PR_SET_PDEATHSIG = 1


class StartError(Exception):
    """Pitlane cannot start; the message says why and what to do."""


@dataclass(frozen=True)
class Pool:
    """A Celery worker serving one queue with its own processes."""

    name: str  # in the supervisor's words: "training worker"
    queue: str
    hostname: str  # unique per worker on a machine: each has its own heartbeat (console.workers)
    concurrency: int
    niceness: int = 0  # its processes' and their children's: 10 gives way to everyone at 0

    def command(self) -> list[str]:
        """The worker's whole command line: ``nice`` first where it yields the cores."""
        niced = ["nice", "-n", str(self.niceness)] if self.niceness else []
        return [*niced, sys.executable, "-m", "celery", *self.arguments()]

    def arguments(self) -> list[str]:
        """``celery -A console worker`` and what follows it, for this pool."""
        processes = ["--concurrency", str(self.concurrency)]
        named = ["-Q", self.queue, "--hostname", self.hostname, *processes]
        return ["-A", "console", "worker", *named, "--loglevel", "INFO"]


def worker_pools(*, trainers: int, simulations: int, prefix: str = "") -> list[Pool]:
    """The workers of one machine, one per queue (``settings.PITLANE_QUEUES``): ``trainers`` jobs
    train at once, ``simulations`` processes drive their rollouts, evaluations and races, and one
    process re-scores (analysis.rescore: minutes of a racer's reward function, taking no more).
    The re-scoring yields the cores to the trainings: a racer's look back at driving already
    done waits where a club's trainings would otherwise lose a core to it (issue 56's evening)."""
    return [
        Pool("training worker", "training", f"{prefix}trainer@%h", trainers),
        Pool("simulation worker", "simulation", f"{prefix}sim@%h", simulations),
        Pool("re-scoring worker", "rescoring", f"{prefix}rescore@%h", 1, niceness=10),
    ]


@dataclass
class Child:
    name: str
    process: subprocess.Popen
    command: list[str]
    started: float = field(default_factory=time.monotonic)
    deaths: int = 0  # in a row: a child that stays up STEADY seconds starts again from zero
    restart_at: float | None = None  # [monotonic] when a dead child is started again


@dataclass
class Supervisor:
    host: str
    port: int
    var_dir: Path
    local_redis_port: int | None  # None: REDIS_URL names a Redis that someone else runs
    sizing: Sizing  # the trainers, simulation processes, cars and threads chosen for the machine
    out: IO[str] = field(default_factory=lambda: sys.stdout)
    children: list[Child] = field(default_factory=list)
    _stopping: bool = False

    @classmethod
    def from_environment(cls) -> Supervisor:
        return cls(
            host=env.str("PITLANE_HOST", "127.0.0.1"),
            port=env.int("PITLANE_PORT", 8000, minimum=1, maximum=65535),
            var_dir=settings.VAR_DIR,
            local_redis_port=None if "REDIS_URL" in os.environ else settings.REDIS_PORT,
            sizing=settings.SIZING,  # each figure the environment's where it sets one
        )

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}"

    def run(self) -> int:
        """Start everything, serve (restarting a child that dies) until Ctrl-C, then stop
        everything."""
        files_private()  # what it and its children create under var/ is their owner's alone
        private_dir(self.var_dir)
        with _InstanceLock(self.var_dir):
            data_dir_private(self.var_dir)  # what an earlier install left readable to others
            _check_port(self.host, self.port, "the web server", "PITLANE_PORT")
            if self.local_redis_port is not None:
                _check_port("127.0.0.1", self.local_redis_port, "Redis", "PITLANE_REDIS_PORT")
            for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                signal.signal(signum, self._request_stop)
            try:
                self._start()
                return self._watch()
            finally:
                self._stop_children()

    # Start-up

    def _start(self) -> None:
        if self.local_redis_port is not None:
            self._start_redis(self.local_redis_port)
        self._wait_for_redis()
        self._say("Preparing the database...")
        call_command("migrate", interactive=False, verbosity=0)
        call_command("loadtracks", stdout=self.out)
        call_command("loaddemoseason", stdout=self.out)
        self._say(self.sizing.in_words())
        pools = worker_pools(trainers=self.sizing.trainers, simulations=self.sizing.simulations)
        for pool in pools:
            # the scheduler (the monthly promotion, a simulation task) runs inside one worker
            beat = ["--beat"] if pool.queue == "simulation" else []
            self._spawn(pool.name, [*pool.command(), *beat])
        self._spawn(
            "web server",
            [
                sys.executable,
                "-m",
                "daphne",
                "-b",
                self.host,
                "-p",
                str(self.port),
                "console.asgi:application",
            ],
        )
        self._wait_until(self._workers_reported, "the Celery workers to report in")
        self._wait_until(self._web_answers, "the web server to answer")
        self._say(f"\nPitlane is running: {self.url}  (Ctrl-C stops it)\n")

    def _start_redis(self, port: int) -> None:
        executable = shutil.which("redis-server")
        if executable is None:
            raise StartError(
                "redis-server is not installed. `make run` installs it with apt where it can; "
                "elsewhere install Redis 6 or newer, or set REDIS_URL to a Redis you run."
            )
        data = self.var_dir / "redis"
        data.mkdir(parents=True, exist_ok=True)
        self._say(f"Starting Redis on 127.0.0.1:{port} (data in {data})...")
        # The password (settings.REDIS_PASSWORD) goes in a file only its owner reads, not on the
        # command line, which every user of the machine can list.
        config = data / "redis.conf"
        config.touch(mode=0o600)
        config.chmod(0o600)
        config.write_text(f"requirepass {settings.REDIS_PASSWORD}\n")
        self._spawn(
            "Redis",
            [
                executable,
                str(config),
                "--bind",
                "127.0.0.1",
                "--port",
                str(port),
                "--dir",
                str(data),
                "--appendonly",
                "yes",
                "--protected-mode",
                "yes",
                "--daemonize",
                "no",
                "--logfile",
                str(data / "redis.log"),
            ],
        )

    def _wait_for_redis(self) -> None:
        client = redis_client()

        def answers() -> bool:
            try:
                return bool(client.ping())
            except redis.BusyLoadingError:
                return False  # replaying the append-only file
            except redis.RedisError:
                return False

        self._wait_until(answers, f"Redis at {_redact(settings.REDIS_URL)}")

    def _workers_reported(self) -> bool:
        started = {c.process.pid for c in self.children if c.command[1:3] == ["-m", "celery"]}
        try:
            return started <= {w["pid"] for w in live_workers(redis_client())}
        except redis.RedisError:
            return False

    def _web_answers(self) -> bool:
        try:
            with urllib.request.urlopen(f"{self.url}/healthz", timeout=2):  # noqa: S310
                return True
        except urllib.error.HTTPError:
            return True  # it answered; what /healthz says is for the operator to read
        except OSError:
            return False

    def _wait_until(self, ready: Callable[[], bool], what: str) -> None:
        deadline = time.monotonic() + START_TIMEOUT
        while not ready():
            self._check_children()
            if self._stopping:
                raise StartError("Stopped before start-up finished.")
            if time.monotonic() > deadline:
                raise StartError(f"Gave up waiting for {what} after {START_TIMEOUT:.0f} s.")
            time.sleep(0.2)

    def _spawn(self, name: str, command: list[str]) -> None:
        self.children.append(Child(name, _popen(command, self.sizing), command))

    # Serving and stopping

    def _watch(self) -> int:
        while not self._stopping:
            for child in self.children:
                self._tend(child, time.monotonic())
            time.sleep(0.5)
        return 0

    def _tend(self, child: Child, now: float) -> None:
        """Restart ``child`` if it died and its pause is over; schedule the pause when it has
        just died. Its work goes on: a trainer's job by its lease, from its last checkpoint; an
        unacknowledged task is delivered again; workers and the web server reconnect to a Redis
        started again (its data kept in its append-only file)."""
        if child.restart_at is not None:
            if now >= child.restart_at and not self._stopping:
                child.process, child.restart_at = _popen(child.command, self.sizing), None
                child.started = now
                self._say(f"Started the {child.name} again (process {child.process.pid}).")
            return
        code = child.process.poll()
        if code is None:
            if child.deaths and now - child.started >= STEADY:
                child.deaths = 0
            return
        _kill_group(child.process)
        delay = RESTART_DELAYS[min(child.deaths, len(RESTART_DELAYS) - 1)]
        child.deaths += 1
        child.restart_at = now + delay
        self._say(
            f"The {child.name} stopped unexpectedly (exit status {code}); its output is above. "
            f"Starting it again in {delay:.0f} s."
        )

    def _check_children(self) -> None:
        """During start-up, a child that dies stops everything: it will not start by itself."""
        for child in self.children:
            code = child.process.poll()
            if code is not None and not self._stopping:
                raise StartError(
                    f"The {child.name} stopped while Pitlane was starting (exit status {code}); "
                    "its output is above. Stopping Pitlane."
                )

    def _request_stop(self, signum: int, frame: object) -> None:
        if not self._stopping:
            self._say("\nStopping Pitlane...")
        self._stopping = True

    def _stop_children(self) -> None:
        self._stopping = True
        for child in reversed(self.children):
            if child.process.poll() is None:
                child.process.terminate()
                try:
                    child.process.wait(STOP_GRACE)
                except subprocess.TimeoutExpired:
                    self._say(f"The {child.name} did not stop in {STOP_GRACE:.0f} s; killing it.")
                    child.process.kill()
                    child.process.wait()
            _kill_group(child.process)
        self.children.clear()
        Path(settings.PITLANE_POLICY_SOCKET).unlink(missing_ok=True)  # the policy server ends

    def _say(self, text: str) -> None:
        self.out.write(text + "\n")
        self.out.flush()


class _InstanceLock:
    """An exclusive lock on var/run.lock for as long as the supervisor runs."""

    def __init__(self, var_dir: Path) -> None:
        self.path = var_dir / "run.lock"
        self.var_dir = var_dir
        self.file: IO[str] | None = None

    def __enter__(self) -> _InstanceLock:
        self.file = open(self.path, "a+")
        try:
            fcntl.flock(self.file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.file.seek(0)
            pid = self.file.read().strip() or "unknown"
            self.file.close()
            raise StartError(
                f"Pitlane is already running with its data in {self.var_dir} (process {pid}). "
                "Use that one at its URL, or stop it with Ctrl-C in its terminal first."
            ) from None
        self.file.seek(0)
        self.file.truncate()
        self.file.write(str(os.getpid()))
        self.file.flush()
        return self

    def __exit__(self, *exc_info: object) -> None:
        assert self.file is not None
        self.file.truncate(0)
        fcntl.flock(self.file, fcntl.LOCK_UN)
        self.file.close()


def _check_port(host: str, port: int, what: str, variable: str) -> None:
    """Raise ``StartError`` when something already listens on ``host:port``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError:
            raise StartError(
                f"Port {port} is already in use by another program, so {what} cannot start. "
                f"Stop that program, or choose another port: {variable}={port + 1} make run"
            ) from None


def _popen(command: list[str], sizing: Sizing) -> subprocess.Popen:
    """Start ``command`` with the figures chosen for the machine in its environment: a child
    (re)started once memory has changed counts the same trainers as the workers beside it."""
    return subprocess.Popen(
        command,
        cwd=settings.BASE_DIR,
        env={**os.environ, **sizing.environment()},
        start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops us in order
        preexec_fn=_stop_with_parent,
    )


def _kill_group(process: subprocess.Popen) -> None:
    """Kill what is left of an ended child's process group: a worker killed outright leaves its
    pool's processes behind, holding their memory (and the terminal's output) for ever, and
    perhaps still running a task that its restarted worker will be given again."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)


def _stop_with_parent() -> None:
    """In the child, before exec: have the kernel send SIGTERM when the supervisor dies."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
