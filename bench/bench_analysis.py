"""The Analysis tab of a 10-hour job: 200 iterations, 2 million recorded steps.

    python -m bench.bench_analysis [--iterations 200] [--steps 10000] [--requests 50]

Drives the simulator once for ``--steps`` steps (the centre-line driver with its steering
jittered, so episodes lap, leave the track and crash into nothing alike), writes that trace as
every one of ``--iterations`` iterations of one job, and summarises each as the trainer does when
it records it (the time that adds to an iteration is printed). Then it asks, through Django's
whole request stack as the racer's browser does, for the page and for the data its script
fetches: all iterations, the last ten, one outcome, the map's points, one episode's steps, and
prints p50/p95 per request (target: the page and each request p95 under 300 ms). Last, it
re-scores one iteration with another reward function, as a simulation worker does, and prints
the steps scored per second.

The database is a fresh SQLite file, storage a temporary folder: local disk, as ``make run``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--steps", type=int, default=10_000, help="recorded steps per iteration")
    parser.add_argument("--requests", type=int, default=50, help="per kind of request")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-analysis-") as folder:
        os.environ["DATABASE_URL"] = f"sqlite:///{folder}/bench.sqlite3"
        os.environ["PITLANE_VAR_DIR"] = folder
        os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
        measure(args)


def driven(steps: int) -> str:
    """``steps`` steps of the simulator's trace, as one iteration's CSV."""
    import gymnasium
    import numpy as np

    import simulator
    from simulator.controller import CentreLineDriver
    from simulator.trace import to_csv

    env = gymnasium.make(simulator.ENV_ID, track="pitlane-oval")
    rng = np.random.default_rng(7)
    rows, episode = [], 0
    while len(rows) < steps:
        _, info = env.reset(seed=7) if episode == 0 else env.reset()  # a seed starts over
        rows.append(info["trace"])
        driver = CentreLineDriver(env.unwrapped)
        jitter = rng.uniform(0, 4)  # how many actions away from the driver's it may stray
        while len(rows) < steps:
            action = int(np.clip(driver.act() + round(rng.normal(0, jitter)), 0, 9))
            _, _, terminated, truncated, info = env.step(action)
            rows.append(info["trace"])
            if terminated or truncated:
                break
        episode += 1
    env.close()
    return to_csv(rows)


def measure(args) -> None:
    import django

    django.setup()
    from django.conf import settings
    from django.contrib.auth.models import User
    from django.core.management import call_command
    from django.test import Client

    from analysis import records, traces
    from rl import hyperparameters
    from training import artifacts, configuration
    from training.models import RLModel, TrainingJob
    from training.rewards import EXAMPLES

    settings.ALLOWED_HOSTS = [*settings.ALLOWED_HOSTS, "testserver"]
    call_command("migrate", verbosity=0)
    call_command("loadtracks", verbosity=0, stdout=open(os.devnull, "w"))  # noqa: SIM115
    racer = User.objects.create_user("racer", password="!")  # noqa: S106
    draft = {
        "name": "ten-hours",
        "track": "pitlane-oval",
        "reward_function": EXAMPLES[0].source,
        "hyperparameters": hyperparameters.defaults("clipped_ppo"),
    }
    clean = configuration.check(draft, owner=racer, validate_reward=False)
    model = RLModel.objects.create(owner=racer, status=RLModel.Status.READY, **clean.row())
    job = TrainingJob.objects.create(
        model=model, status=TrainingJob.Status.COMPLETED, iterations=args.iterations
    )

    started = time.perf_counter()
    document = driven(args.steps)
    episodes = traces.read(document).episodes()
    middle = episodes[len(episodes) // 2]
    print(f"drove {args.steps:,} steps in {time.perf_counter() - started:.1f} s", flush=True)
    summarising = []
    for iteration in range(1, args.iterations + 1):
        artifacts.save(model, artifacts.training_trace(iteration), document)
        begin = time.perf_counter()
        records.summarize_document(document, job=job, iteration=iteration)
        summarising.append(time.perf_counter() - begin)
    total = args.iterations * (document.count("\n") - 1)
    print(
        f"{args.iterations} iterations, {total:,} recorded rows; summarising one as the trainer "
        f"records it: {statistics.median(summarising) * 1000:.0f} ms (median)"
    )
    print(f"{len(episodes)} episodes an iteration; the one shown: {middle.steps} steps\n")

    client = Client()
    client.force_login(racer)
    base = f"/models/{model.pk}/analysis/"
    last = args.iterations
    one = f"iteration={last}&episode={middle.number}"
    cases = [
        ("the page (HTML, the track, every iteration's figures)", base),
        ("data.json, every iteration", f"{base}data.json"),
        ("data.json, the last 10 iterations", f"{base}data.json?first={last - 9}&last={last}"),
        ("data.json, off-track episodes only", f"{base}data.json?outcomes=off_track"),
        ("points.bin, every iteration (60,000 of them)", f"{base}points.bin"),
        ("points.bin, the last 10 iterations", f"{base}points.bin?first={last - 9}&last={last}"),
        ("episode.json, one episode's steps and params", f"{base}episode.json?{one}"),
    ]  # fmt: skip
    print(f"{'request':56} {'p50 [ms]':>9} {'p95 [ms]':>9} {'size [kB]':>10}")
    for label, path in cases:
        for _ in range(3):  # warm, as a running server is
            response = client.get(path)
            assert response.status_code == 200, (path, response.status_code)
        times = []
        for _ in range(args.requests):
            begin = time.perf_counter()
            response = client.get(path)
            times.append((time.perf_counter() - begin) * 1000)
        times.sort()
        p95 = times[max(0, int(0.95 * len(times)) - 1)]
        size = len(response.content) / 1000
        print(f"{label:56} {statistics.median(times):9.1f} {p95:9.1f} {size:10.0f}", flush=True)
    rescore(job, racer, last)


def rescore(job, racer, last: int) -> None:
    """Time a re-scoring of the last iteration with DeepRacer's centre-line example, in the
    sandbox as a simulation worker runs it."""
    from analysis import rescoring
    from analysis.models import Rescoring
    from training.rewards import EXAMPLES

    # As the page asks for one (analysis.services), without a broker: this process runs it.
    asked = Rescoring.objects.create(
        owner=racer,
        job=job,
        reward_function=EXAMPLES[0].source,
        first=last,
        last=last,
        total_steps=job.summaries.get(iteration=last).steps,
    )
    begin = time.perf_counter()
    rescoring.run(asked.pk)
    seconds = time.perf_counter() - begin
    asked.refresh_from_db()
    assert asked.status == "DONE", asked.failure
    print(
        f"\nre-scoring one iteration ({asked.steps:,} steps) with the centre-line example: "
        f"{seconds:.1f} s, {asked.steps / seconds:,.0f} steps/s (the sandbox's start included)"
    )


if __name__ == "__main__":
    sys.exit(main())
