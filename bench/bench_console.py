"""Console start-up and page latency: `python -m bench.bench_console` (or `make bench`).

Starts the whole console the way `make run` does (its own Redis, one Celery worker, Daphne) in a
scratch directory on free ports, times how long it takes to serve, then requests each page
sequentially and prints p50/p95 latencies. Nothing here runs in the test suite.
"""

from __future__ import annotations

import statistics
import time
import urllib.request

from bench.stack import running_console

PAGES = ["/", "/races/", "/leaderboards/", "/healthz"]
REQUESTS = 200  # per page, after 10 warm-up requests


def percentile(samples: list[float], fraction: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, round(fraction * (len(ordered) - 1)))]


def main() -> None:
    with running_console() as console:
        print(
            f"Cold start to serving (empty database, migrations included): "
            f"{console['ready_seconds']:.1f} s"
        )
        print(f"{'page':<16}{'p50 [ms]':>10}{'p95 [ms]':>10}")
        for page in PAGES:
            url = console["url"] + page
            samples = []
            for attempt in range(10 + REQUESTS):
                begin = time.perf_counter()
                with urllib.request.urlopen(url, timeout=10) as response:  # noqa: S310
                    response.read()
                if attempt >= 10:
                    samples.append((time.perf_counter() - begin) * 1000)
            print(
                f"{page:<16}{statistics.median(samples):>10.1f}{percentile(samples, 0.95):>10.1f}"
            )


if __name__ == "__main__":
    main()
