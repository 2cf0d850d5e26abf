"""Live streams: frame latency, frames/s per viewer, and what viewers cost training.

`python -m bench.bench_live` starts the console as `make run` does and trains a model with
DeepRacer's defaults (as bench_training does). Each viewer is a websocket client through Daphne
with a logged-in session, acknowledging each frame as a page does once it has drawn it. The
viewers run in a process of their own at the lowest CPU priority: they stand for browsers on
other machines, so they take only the CPU that training leaves idle here, and what they use is
printed apart.

- Latency: from the frame's render in the simulation to its arrival at the viewer's websocket,
  p50 and p95, with 1 and with 20 viewers of one job.
- Frames/s delivered to each of 20 viewers while training goes on: while the car drives, and
  over the whole time (the car waits, one frame a second, while the policy is updated).
- What 20 viewers cost training: the job's iterations alternate between nobody watching and 20
  viewers, so that both kinds run on the same job at the same stage of learning; each
  iteration's throughput is its environment steps over the time from the previous iteration's
  end to its own (driving, evaluation and policy update). Printed: each kind's mean and spread,
  the mean of each watched iteration against the mean of its unwatched neighbours, and the share
  of a core the web server (Daphne), Redis and the viewers used in each kind.
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import os
import statistics
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path

from bench.stack import running_console

VIEWERS = 20
WATCHED = 5  # iterations that 20 viewers watch, each between two that nobody watches
DRIVING_GAP = 0.5  # [s] frames closer than this, and not paused, are of the car driving


@dataclass
class Viewer:
    latencies: list[float] = field(default_factory=list)
    frames: int = 0
    held: int = 0
    driving_frames: int = 0
    driving_seconds: float = 0.0
    started: float = 0.0
    stopped: float = 0.0


async def watch(url: str, headers: dict, viewer: Viewer, stop: asyncio.Event) -> None:
    import websockets

    async with websockets.connect(url, additional_headers=headers, max_size=None) as socket:
        viewer.started = time.monotonic()
        last_driving = None
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
            if header.get("paused"):
                viewer.held += 1
                last_driving = None
            else:
                now = time.monotonic()
                if last_driving is not None and now - last_driving < DRIVING_GAP:
                    viewer.driving_frames += 1
                    viewer.driving_seconds += now - last_driving
                last_driving = now
            await socket.send('{"type": "ack"}')
        viewer.stopped = time.monotonic()


def audience(url: str, headers: dict, count: int, pipe) -> None:
    """A viewers' process: ``count`` viewers until told to stop; their figures go back by
    ``pipe``."""
    os.nice(19)
    viewers = [Viewer() for _ in range(count)]

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        loop.add_reader(pipe.fileno(), stop.set)
        await asyncio.gather(*(watch(url, headers, v, stop) for v in viewers))

    asyncio.run(main())
    pipe.recv()
    pipe.send(viewers)


class Audience:
    """``count`` viewers of one job, in a process of their own, until ``close``."""

    def __init__(self, base: str, job_id: int, cookie: str, count: int) -> None:
        url = base.replace("http", "ws", 1) + f"/ws/jobs/{job_id}/"
        headers = {"Cookie": cookie, "Origin": base}
        context = multiprocessing.get_context("spawn")
        self.pipe, theirs = context.Pipe()
        self.process = context.Process(target=audience, args=(url, headers, count, theirs))
        self.process.start()

    @property
    def pids(self) -> list[int]:
        return [self.process.pid]

    def close(self) -> list[Viewer]:
        self.pipe.send("stop")
        viewers = self.pipe.recv()
        self.process.join(30)
        return viewers


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


def latency_line(viewers: list[Viewer]) -> str:
    latencies = sorted(x for v in viewers for x in v.latencies)
    if not latencies:
        return "no frames arrived"
    p50 = statistics.median(latencies) * 1000
    p95 = latencies[int(0.95 * (len(latencies) - 1))] * 1000
    return f"p50 {p50:.0f} ms, p95 {p95:.0f} ms over {len(latencies):,} frames"


def frames_line(viewers: list[Viewer]) -> str:
    driving = [v.driving_frames / v.driving_seconds for v in viewers if v.driving_seconds]
    overall = [v.frames / max(v.stopped - v.started, 1e-9) for v in viewers]
    held = sum(v.held for v in viewers) / max(sum(v.frames for v in viewers), 1)
    return (
        f"{min(driving, default=0):.1f}-{max(driving, default=0):.1f} frames/s each while the "
        f"car drives (mean {statistics.mean(driving or [0]):.1f}); "
        f"{statistics.mean(overall):.1f} frames/s over the whole time "
        f"({held:.0%} of the frames show the car waiting for a policy update)"
    )


def spread(rates: list[float]) -> str:
    deviation = statistics.stdev(rates) if len(rates) > 1 else 0.0
    return f"{statistics.mean(rates):,.1f} ± {deviation:,.1f} steps/s"


def main() -> None:
    with running_console(concurrency=3) as console:
        os.environ.update(console["env"])
        import django

        django.setup()
        from django.conf import settings
        from django.test import Client

        from bench.bench_training import bench_racer, default_model, job_of
        from training.models import Iteration
        from training.services import training_stop

        owner = bench_racer()
        client = Client()
        client.force_login(owner)
        session = client.cookies[settings.SESSION_COOKIE_NAME].value
        cookie = f"{settings.SESSION_COOKIE_NAME}={session}"
        servers = server_processes(console)

        model = default_model(owner, "live")
        job = job_of(model)

        def iterations() -> int:
            return Iteration.objects.filter(job=job).count()

        def next_iteration(after: int) -> None:
            while iterations() <= after:
                time.sleep(0.1)

        # The first iteration pays for the worker's first sandbox and PyTorch's start-up; one
        # viewer watches the second.
        next_iteration(0)
        one = Audience(console["url"], job.pk, cookie, 1)
        next_iteration(1)
        print(f"1 viewer: latency {latency_line(one.close())}", flush=True)
        rates: dict[bool, list[float]] = {False: [], True: []}
        cpu: dict[bool, dict[str, list[float]]] = {False: {}, True: {}}
        crowd: list[Viewer] = []
        print(
            f"Training, PPO defaults, camera, one worker: {2 * WATCHED + 1} iterations, every "
            f"other one watched by {VIEWERS} viewers",
            flush=True,
        )
        for phase in range(2 * WATCHED + 1):
            watched, done = phase % 2 == 1, iterations()
            viewers = Audience(console["url"], job.pk, cookie, VIEWERS) if watched else None
            processes = {**servers, "viewers": viewers.pids if viewers else []}
            before = {name: cpu_seconds(pids) for name, pids in processes.items()}
            started = time.monotonic()
            next_iteration(done)
            wall = time.monotonic() - started
            for name, pids in processes.items():
                used = (cpu_seconds(pids) - before[name]) / wall
                cpu[watched].setdefault(name, []).append(used)
            if viewers:
                crowd += viewers.close()
            rows = Iteration.objects.filter(job=job).order_by("number")
            previous, row = rows[done - 1 : done + 1]
            rate = row.steps / (row.created_at - previous.created_at).total_seconds()
            rates[watched].append(rate)
            print(
                f"iteration {row.number}: {rate:,.1f} steps/s, "
                f"{'watched' if watched else 'nobody watching'}",
                flush=True,
            )
        training_stop(job=job_of(model))

        print(f"{VIEWERS} viewers: latency {latency_line(crowd)}")
        print(f"{VIEWERS} viewers: {frames_line(crowd)}")
        alone, watched = rates[False], rates[True]
        # Each watched iteration against its unwatched neighbours: learning changes the episodes'
        # lengths, and so the throughput, as the job goes on.
        paired = [rate / statistics.mean(alone[i : i + 2]) - 1 for i, rate in enumerate(watched)]
        print(f"nobody watching: {spread(alone)}; {VIEWERS} viewers: {spread(watched)}")
        print(
            f"{VIEWERS} viewers against nobody: {statistics.mean(paired):+.1%} "
            f"(each watched iteration against its neighbours: "
            f"{', '.join(f'{x:+.1%}' for x in paired)})"
        )
        for watched in (False, True):
            shares = ", ".join(
                f"{name} {statistics.mean(used):.1%}" for name, used in cpu[watched].items()
            )
            print(f"of one core, {'watched' if watched else 'nobody watching'}: {shares}")


if __name__ == "__main__":
    main()
