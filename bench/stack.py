"""The whole console, started for a benchmark as `make run` starts it, in a scratch directory."""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@contextlib.contextmanager
def sigterm_exits() -> Iterator[None]:
    """Within the block, SIGTERM (``kill``) raises SystemExit as Ctrl-C raises KeyboardInterrupt,
    so that the ``finally`` clauses run: a benchmark stopped either way stops its console."""

    def stop(signum: int, frame) -> None:
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def add_policy_option(parser: argparse.ArgumentParser) -> None:
    """``--policy``: where the cars' policy runs (``PITLANE_ROLLOUT_DEVICE``)."""
    parser.add_argument(
        "--policy",
        default="auto",
        choices=("auto", "cpu", "cuda", "child"),
        help="where the cars' policy runs (PITLANE_ROLLOUT_DEVICE): the machine's server, or child",
    )


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextlib.contextmanager
def running_console(concurrency: int = 2, settings: dict[str, str] | None = None) -> Iterator[dict]:
    """Serve the console (its own Redis, a Celery worker per queue, Daphne) until the block ends;
    yields {"url", "var_dir", "ready_seconds", "env"}; ``env`` points Django at the same database.
    ``settings``: more environment variables for the console (``PITLANE_TRAINERS``, a rate)."""
    with sigterm_exits(), tempfile.TemporaryDirectory(prefix="pitlane-bench-") as var_dir:
        port = free_port()
        env = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
        env.pop("REDIS_URL", None)
        env.update(
            DJANGO_SETTINGS_MODULE="console.settings.dev",
            PITLANE_VAR_DIR=var_dir,
            PITLANE_PORT=str(port),
            PITLANE_REDIS_PORT=str(free_port()),
            PITLANE_WORKER_CONCURRENCY=str(concurrency),
            PYTHONUNBUFFERED="1",
        )
        env.update(settings or {})
        started = time.perf_counter()
        console = subprocess.Popen(
            [sys.executable, "manage.py", "runconsole"],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            for line in console.stdout:
                if "Pitlane is running" in line:
                    break
            else:
                sys.exit("The console did not start; run `make run` to see why.")
            ready = time.perf_counter() - started
            # Keep reading what the console prints, so its processes never block on a full pipe.
            threading.Thread(target=lambda: [None for _ in console.stdout], daemon=True).start()
            yield {
                "url": f"http://127.0.0.1:{port}",
                "var_dir": var_dir,
                "ready_seconds": ready,
                "env": {k: env[k] for k in env if k.startswith(("DJANGO_", "PITLANE_"))},
            }
        finally:
            console.send_signal(signal.SIGINT)
            console.wait(120)


@contextlib.contextmanager
def private_redis(var_dir: str | Path, executable: str | None = None) -> Iterator[str]:
    """A Redis of the benchmark's own on a free port of 127.0.0.1, its data under ``var_dir``,
    until the block ends; yields its URL. ``executable``: the redis-server to run (the one on
    the PATH unless said: on the device machine, Debian's package unpacked under /tmp)."""
    executable = executable or shutil.which("redis-server")
    if executable is None:
        sys.exit("redis-server is not installed (scripts/device-bundle.sh carries Debian's).")
    port = free_port()
    server = subprocess.Popen(
        [
            executable,
            "--bind",
            "127.0.0.1",
            "--port",
            str(port),
            "--dir",
            str(var_dir),
            "--save",
            "",
            "--appendonly",
            "no",
            "--logfile",
            str(Path(var_dir) / "redis.log"),
        ],
        stdin=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1):
                break
            if server.poll() is not None or time.monotonic() > deadline:
                sys.exit(f"Redis did not start; see {Path(var_dir) / 'redis.log'}.")
            time.sleep(0.1)
        yield f"redis://127.0.0.1:{port}/0"
    finally:
        server.terminate()
        server.wait(30)


@contextlib.contextmanager
def started(commands: dict[str, list[str]], env: dict[str, str], log_dir: str | Path):
    """Run each of ``commands`` (name: argv) from the repository's root, each in its own session
    with its output in ``log_dir/<name>.log``, until the block ends; then SIGTERM each (SIGKILL
    past a minute) and what it started. Yields the processes by name."""
    processes = {}
    try:
        for name, argv in commands.items():
            with open(Path(log_dir) / f"{name}.log", "wb") as log:
                processes[name] = subprocess.Popen(
                    argv,
                    cwd=ROOT,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
        yield processes
    finally:
        for process in reversed(processes.values()):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGTERM)
            try:
                process.wait(60)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)
