"""What a web process costs to start: `python -m bench.bench_startup [--tree PATH] [--runs N]`.

Starts, ``--runs`` times, a fresh Python that does what Daphne does before its first request
(loads ``console.asgi``: Django set up, the HTTP and websocket routes) and what the first
requests do (every URL's view module, the admin's pages), then prints the median wall time of
that and the process's resident memory after it, with the heavy libraries it loaded. ``--tree``
measures another checkout of the code (a worktree of an older commit) the same way, for a
before-and-after.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

HEAVY = ("torch", "pybullet", "cv2", "stable_baselines3", "gymnasium", "onnx")

WEB_PROCESS = """
import json, sys, time
started = time.perf_counter()
import console.asgi
from django.contrib import admin
from django.urls import get_resolver

def walk(patterns):
    for pattern in patterns:
        walk(getattr(pattern, "url_patterns", []))

walk(get_resolver().url_patterns)
admin.site.get_urls()
took = time.perf_counter() - started
rss = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmRSS"))
heavy = sorted({name.split(".")[0] for name in sys.modules} & set(%r))
print(json.dumps({"seconds": took, "rss_kib": rss, "heavy": heavy}))
"""


def start(tree: Path) -> dict:
    environment = {**os.environ, "DJANGO_SETTINGS_MODULE": "console.settings.dev"}
    environment["PYTHONDONTWRITEBYTECODE"] = "1"
    done = subprocess.run(
        [sys.executable, "-c", WEB_PROCESS % (HEAVY,)],
        cwd=tree, env=environment, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tree", type=Path, default=Path(__file__).resolve().parent.parent,
                        help="the checkout to start (default: this one)")  # fmt: skip
    parser.add_argument("--runs", type=int, default=7)
    arguments = parser.parse_args()
    start(arguments.tree)  # a first start warms the file cache and writes no figure
    runs = [start(arguments.tree) for _ in range(arguments.runs)]
    seconds = statistics.median(run["seconds"] for run in runs)
    memory = statistics.median(run["rss_kib"] for run in runs) / 1024
    print(f"A web process of {arguments.tree}, median of {arguments.runs} starts:")
    print(f"  import and set-up time: {seconds * 1000:.0f} ms")
    print(f"  resident memory: {memory:.0f} MiB")
    print(f"  heavy libraries loaded: {', '.join(runs[0]['heavy']) or 'none'}")


if __name__ == "__main__":
    main()
