"""What a web process loads before its first request, and what a validation costs it:
`python -m bench.bench_web_startup`.

Each round starts a fresh interpreter that does what Daphne does before it serves (``console.asgi``,
which sets Django up) and then loads every URL pattern, as the first request does; it reports
the time that took, the process's peak memory, and which of the heavy libraries the web tier
should not need came in (PyTorch, PyBullet, OpenCV, stable-baselines3). Then one interpreter
validates our follow-the-centre-line example on the Rookie Loop, as the editor's Validate does
(static checks, then a sandbox child that makes the five sample situations and runs the code on
them): the median time of a validation after a first one. ``--tree`` measures another checkout
of the code (a worktree of an older commit) the same way, for a before-and-after.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

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

VALIDATE = f"""
import json, statistics, time
import django
django.setup()
from training.rewards import EXAMPLES, reward_validate
times = []
for _ in range({ROUNDS} + 1):
    started = time.perf_counter()
    assert reward_validate(source=EXAMPLES[0].source, track="rookie-loop").valid
    times.append(time.perf_counter() - started)
print(json.dumps({{"seconds": statistics.median(times[1:])}}))
"""


def run_probe(probe: str, var_dir: str, tree: Path) -> dict:
    env = {
        **os.environ,
        "DJANGO_SETTINGS_MODULE": "console.settings.dev",
        "PITLANE_VAR_DIR": var_dir,
    }
    output = subprocess.run(
        [sys.executable, "-c", probe],
        env=env,
        cwd=tree,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return json.loads(output.splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument(
        "--tree",
        type=Path,
        default=Path(__file__).resolve().parent.parent,
        help="the checkout to start (default: this one)",
    )
    tree = parser.parse_args().tree
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-web-") as var_dir:
        run_probe(PROBE, var_dir, tree)  # the first start fills the file system's cache
        starts = [run_probe(PROBE, var_dir, tree) for _ in range(ROUNDS)]
        validation = run_probe(VALIDATE, var_dir, tree)["seconds"]
    seconds = statistics.median(start["seconds"] for start in starts)
    peak = statistics.median(start["peak_mib"] for start in starts)
    print(
        f"Web process start-up of {tree} (console.asgi and every URL pattern), median of {ROUNDS}:"
    )
    print(f"  import time: {seconds:.2f} s")
    print(f"  peak memory: {peak:.0f} MiB")
    print(f"  heavy libraries loaded: {', '.join(starts[0]['heavy']) or 'none'}")
    print(f"A validation (the centre-line example, Rookie Loop), median of {ROUNDS}:")
    print(f"  {validation:.2f} s")


if __name__ == "__main__":
    main()
