"""The route-file check of a track upload, for the largest file the upload allows.

    python -m bench.bench_route_check [--repeat 5]

Staff add tracks from DeepRacer route files (``training.services.track_add``): the simulator's
loader checks the route (DeepRacer's checks, and that no border crosses itself or the other)
and the admin draws a preview, both before the transaction that writes the row. The file here
is as large as ``ROUTE_MAX_BYTES`` lets through (float64 rows of six), a loop with a wavy
border, so every segment has close neighbours; the figure is the median of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import time

import numpy as np


def route_file(size: int) -> tuple[bytes, int]:
    """A valid route file of at most ``size`` bytes, and its number of waypoints."""
    rows = (size - 128) // (6 * 8)  # numpy.save's header is 128 bytes
    theta = np.linspace(0.0, 2.0 * np.pi, rows)
    radius = 400.0 + 0.5 * np.sin(theta * 400)  # [m] a loop of about 2.5 km, waving
    centre = np.column_stack([radius * np.cos(theta), 0.7 * radius * np.sin(theta)])
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]]) * 0.53
    route = np.hstack([centre, centre + left, centre - left])
    route[-1] = route[0]
    buffer = io.BytesIO()
    np.save(buffer, route)
    return buffer.getvalue(), rows


def timed(step, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        step()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
    import django

    django.setup()
    from simulator import texture, tracks
    from training.services import ROUTE_MAX_BYTES

    data, rows = route_file(ROUTE_MAX_BYTES)
    inline = {"name": "largest", "route": data}
    track = tracks.load(inline)
    check = timed(lambda: tracks.load(inline), args.repeat)
    preview = timed(lambda: texture.preview_png(track), args.repeat)
    print(f"| route file ({len(data) / 2**20:.1f} MiB, {rows:,} waypoints) | seconds |")
    print("|---|---|")
    print(f"| the route's check (simulator.tracks.load) | {check:.2f} |")
    print(f"| the preview (simulator.texture.preview_png) | {preview:.2f} |")


if __name__ == "__main__":
    main()
