"""What a web process loads before its first request: `python -m bench.bench_web_startup`.

Each round starts a fresh interpreter that does what Daphne does before it serves (``console.asgi``,
which sets Django up) and then loads every URL pattern, as the first request does; it reports
the time that took, the process's peak memory, and which of the heavy libraries the web tier
should not need came in (PyTorch, PyBullet, OpenCV, stable-baselines3).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile

ROUNDS = 5
HEAVY = ("torch", "pybullet", "cv2", "stable_baselines3")
PROBE = f"""
import json, resource, sys, time
started = time.perf_counter()
import console.asgi
from django.urls import get_resolver
get_resolver().url_patterns
print(json.dumps({{
    "seconds": time.perf_counter() - started,
    "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "heavy": [name for name in {HEAVY!r} if name in sys.modules],
}}))
"""


def one_start(var_dir: str) -> dict:
    env = {
        **os.environ,
        "DJANGO_SETTINGS_MODULE": "console.settings.dev",
        "PITLANE_VAR_DIR": var_dir,
    }
    output = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, check=True, capture_output=True, text=True
    ).stdout
    return json.loads(output.splitlines()[-1])


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-web-") as var_dir:
        one_start(var_dir)  # the first start fills the file system's cache
        starts = [one_start(var_dir) for _ in range(ROUNDS)]
    seconds = statistics.median(start["seconds"] for start in starts)
    peak = statistics.median(start["peak_mib"] for start in starts)
    print(f"Web process start-up (console.asgi and every URL pattern), median of {ROUNDS}:")
    print(f"  import time: {seconds:.2f} s")
    print(f"  peak memory: {peak:.0f} MiB")
    print(f"  heavy libraries loaded: {', '.join(starts[0]['heavy']) or 'none'}")


if __name__ == "__main__":
    main()
