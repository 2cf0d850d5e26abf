"""Live streams: frame latency, frames/s per viewer, and what viewers cost training.

`python -m bench.bench_live` starts the console as `make run` does and trains two identical models
(DeepRacer's defaults, as in bench_training, same seed): the first with nobody watching, the
second watched first by one viewer, then by twenty. Each viewer is a websocket client through
Daphne with a logged-in session, acknowledging each frame as a page does once it has drawn it.

- Latency: from the frame's render in the simulation to its arrival at the viewer's websocket,
  p50 and p95, with 1 and with 20 viewers of one job.
- Frames/s delivered to each of 20 viewers while training goes on (frames of the car waiting
  during policy updates included, and counted apart).
- Training throughput (environment steps/s to the same number of policy updates) with and
  without the 20 viewers, and the share of a core the web server (Daphne) and Redis use in each
  run: what serving the viewers takes from the machine, apart from the run-to-run spread.
"""

from __future__ import annotations

import asyncio
import json
import os
import statistics
import struct
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from bench.stack import running_console

ITERATIONS = 4  # policy updates each run trains for
ONE_VIEWER_SECONDS = 30.0
VIEWERS = 20


@dataclass
class Viewer:
    latencies: list[float] = field(default_factory=list)
    frames: int = 0
    held: int = 0
    started: float = 0.0
    stopped: float = 0.0


async def watch(url: str, headers: dict, viewer: Viewer, stop: threading.Event) -> None:
    import websockets

    async with websockets.connect(url, additional_headers=headers, max_size=None) as socket:
        viewer.started = time.monotonic()
        while not stop.is_set():
            try:
                message = await asyncio.wait_for(socket.recv(), timeout=0.5)
            except TimeoutError:
                continue
            if isinstance(message, str):
                continue
            arrived = time.time()
            (length,) = struct.unpack("!I", message[:4])
            header = json.loads(message[4 : 4 + length])
            viewer.latencies.append(arrived - header["rendered_at"])
            viewer.frames += 1
            viewer.held += bool(header.get("paused"))
            await socket.send('{"type": "ack"}')
        viewer.stopped = time.monotonic()


class Audience:
    """``count`` viewers of one job, in a thread of their own, until ``close``."""

    def __init__(self, base: str, job_id: int, cookie: str, count: int) -> None:
        self.viewers = [Viewer() for _ in range(count)]
        self.stop = threading.Event()
        url = base.replace("http", "ws", 1) + f"/ws/jobs/{job_id}/"
        headers = {"Cookie": cookie, "Origin": base}

        async def main() -> None:
            await asyncio.gather(*(watch(url, headers, v, self.stop) for v in self.viewers))

        self.thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)
        self.thread.start()

    def close(self) -> list[Viewer]:
        self.stop.set()
        self.thread.join(30)
        return self.viewers


def server_processes(console: dict) -> dict[str, list[int]]:
    """The pids of the console's Daphne and Redis, found by their command lines."""
    found: dict[str, list[int]] = {"Daphne": [], "Redis": []}
    port, redis_port = console["env"]["PITLANE_PORT"], console["env"]["PITLANE_REDIS_PORT"]
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if "daphne" in command and f"-p {port}" in command:
            found["Daphne"].append(int(entry.name))
        elif "redis-server" in command and redis_port in command:
            found["Redis"].append(int(entry.name))
    return found


def cpu_seconds(pids: list[int]) -> float:
    """User and system CPU time of ``pids`` so far."""
    total = 0
    for pid in pids:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])  # utime, stime
    return total / os.sysconf("SC_CLK_TCK")


class CpuMeter:
    """The share of one core each server process used between ``start`` and ``stop``."""

    def __init__(self, processes: dict[str, list[int]]) -> None:
        self.processes = processes

    def start(self) -> None:
        self.started = time.monotonic()
        self.before = {name: cpu_seconds(pids) for name, pids in self.processes.items()}

    def stop(self) -> str:
        wall = time.monotonic() - self.started
        return ", ".join(
            f"{name} {(cpu_seconds(pids) - self.before[name]) / wall:.1%}"
            for name, pids in self.processes.items()
        )


def train(owner, name: str):
    from bench.bench_training import default_model, job_of

    model = default_model(owner, name)
    while job_of(model).status != "IN_PROGRESS":
        time.sleep(0.5)
    return model


def finish(model, iterations: int = ITERATIONS) -> float:
    """Train to ``iterations`` updates, stop; steps/s over the training time."""
    from bench.bench_training import job_of
    from training.services import training_stop

    while job_of(model).iterations < iterations:
        time.sleep(0.5)
    job = job_of(model)
    rate = job.steps / job.training_seconds
    training_stop(job=job)
    while job_of(model).status != "COMPLETED":
        time.sleep(1)
    return rate


def latency_line(viewers: list[Viewer]) -> str:
    latencies = sorted(x for v in viewers for x in v.latencies)
    if not latencies:
        return "no frames arrived"
    p50 = statistics.median(latencies) * 1000
    p95 = latencies[int(0.95 * (len(latencies) - 1))] * 1000
    return f"p50 {p50:.0f} ms, p95 {p95:.0f} ms over {len(latencies):,} frames"


def main() -> None:
    with running_console(concurrency=3) as console:
        os.environ.update(console["env"])
        import django

        django.setup()
        from django.conf import settings
        from django.contrib.auth.models import User
        from django.test import Client

        from bench.bench_training import job_of

        owner = User.objects.create_user("bench", password="bench-password-1")  # noqa: S106
        client = Client()
        client.force_login(owner)
        session = client.cookies[settings.SESSION_COOKIE_NAME].value
        cookie = f"{settings.SESSION_COOKIE_NAME}={session}"

        # The worker's processes pay once for the sandbox self-test and for loading PyTorch; a
        # first job takes that cost, so that neither measured one does.
        finish(train(owner, "warm-up"), iterations=1)
        print(f"Training to {ITERATIONS} policy updates, PPO defaults, camera, one worker:")
        meter = CpuMeter(server_processes(console))
        model = train(owner, "unwatched")
        meter.start()
        alone = finish(model)
        print(f"nobody watching: {alone:,.1f} steps/s; of one core: {meter.stop()}", flush=True)

        model = train(owner, "watched")
        job_id = job_of(model).pk
        one = Audience(console["url"], job_id, cookie, 1)
        time.sleep(ONE_VIEWER_SECONDS)
        print(f"1 viewer: latency {latency_line(one.close())}", flush=True)
        crowd = Audience(console["url"], job_id, cookie, VIEWERS)
        meter.start()
        watched = finish(model)
        serving = meter.stop()
        viewers = crowd.close()
        print(f"{VIEWERS} viewers: latency {latency_line(viewers)}")
        rates = [v.frames / max(v.stopped - v.started, 1e-9) for v in viewers]
        held = sum(v.held for v in viewers) / max(sum(v.frames for v in viewers), 1)
        print(
            f"{VIEWERS} viewers: {min(rates):.1f}-{max(rates):.1f} frames/s each "
            f"(mean {statistics.mean(rates):.1f}; {held:.0%} of them show the car waiting "
            "for a policy update)"
        )
        print(
            f"{VIEWERS} viewers watching: {watched:,.1f} steps/s "
            f"({(watched - alone) / alone:+.1%} against nobody watching); "
            f"of one core: {serving}"
        )


if __name__ == "__main__":
    main()
