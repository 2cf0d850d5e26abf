"""The whole console, started for a benchmark as `make run` starts it, in a scratch directory."""

from __future__ import annotations

import contextlib
import os
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
def _sigterm_exits() -> Iterator[None]:
    """Within the block, SIGTERM (``kill``) raises SystemExit as Ctrl-C raises KeyboardInterrupt,
    so that the ``finally`` clauses run: a benchmark stopped either way stops its console."""

    def stop(signum: int, frame) -> None:
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@contextlib.contextmanager
def running_console(concurrency: int = 2, settings: dict[str, str] | None = None) -> Iterator[dict]:
    """Serve the console (its own Redis, a Celery worker per queue, Daphne) until the block ends;
    yields {"url", "var_dir", "ready_seconds", "env"}; ``env`` points Django at the same database.
    ``settings``: more environment variables for the console (``PITLANE_TRAINERS``, a rate)."""
    with _sigterm_exits(), tempfile.TemporaryDirectory(prefix="pitlane-bench-") as var_dir:
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
