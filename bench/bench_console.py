"""Console start-up and page latency: `python -m bench.bench_console` (or `make bench`).

Starts the whole console the way `make run` does (its own Redis, one Celery worker, Daphne) in a
scratch directory on free ports, times how long it takes to serve, then requests each page
sequentially and prints p50/p95 latencies. Nothing here runs in the test suite.
"""

from __future__ import annotations

import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = ["/", "/races/", "/leaderboards/", "/healthz"]
REQUESTS = 200  # per page, after 10 warm-up requests


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def percentile(samples: list[float], fraction: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, round(fraction * (len(ordered) - 1)))]


def main() -> None:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
    env.pop("REDIS_URL", None)
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-") as var_dir:
        env.update(
            DJANGO_SETTINGS_MODULE="console.settings.dev",
            PITLANE_VAR_DIR=var_dir,
            PITLANE_PORT=str(port),
            PITLANE_REDIS_PORT=str(free_port()),
            PYTHONUNBUFFERED="1",
        )
        started = time.perf_counter()
        console = subprocess.Popen(
            [sys.executable, "manage.py", "runconsole"],
            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        try:
            for line in console.stdout:
                if "Pitlane is running" in line:
                    break
            else:
                sys.exit("The console did not start; run `make run` to see why.")
            ready_s = time.perf_counter() - started
            print(f"Cold start to serving (empty database, migrations included): {ready_s:.1f} s")
            print(f"{'page':<16}{'p50 [ms]':>10}{'p95 [ms]':>10}")
            for page in PAGES:
                url = f"http://127.0.0.1:{port}{page}"
                samples = []
                for attempt in range(10 + REQUESTS):
                    begin = time.perf_counter()
                    with urllib.request.urlopen(url, timeout=10) as response:
                        response.read()
                    if attempt >= 10:
                        samples.append((time.perf_counter() - begin) * 1000)
                print(
                    f"{page:<16}{statistics.median(samples):>10.1f}"
                    f"{percentile(samples, 0.95):>10.1f}"
                )
        finally:
            console.send_signal(signal.SIGINT)
            console.wait(60)


if __name__ == "__main__":
    main()
