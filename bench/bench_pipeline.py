"""Training throughput without the web tier: `python -m bench.bench_pipeline [--jobs 1 2 4 8]`.

Starts a Redis of its own, a scratch SQLite database (migrated, the built-in tracks loaded) and
the console's Celery workers as `make run` starts them (``console.supervisor.worker_pools``: a
training worker and a simulation worker), but no web server: the real trainer
(``jobs.trainer``) and rollout workers (``jobs.rollouts``, their sandboxes included) over
a real Redis, the Django app Daphne left out (``bench.pipeline_settings``). For each count in
``--jobs``, that many models with DeepRacer's defaults (``bench_training.default_model``: PPO, the
camera, the 3-layer CNN, 20 episodes between updates, the Rookie Loop) train at once for
``--minutes`` from when the last of them starts; then, per job, its sustained steps/s (its
iterations' steps over their wall time, updates included) and where that time went
(``Iteration.time_split``), and the machine's total.

Rollout workers and cars, unless ``--workers`` and ``--cars`` say (``layout``). The figure the
issue asks for is one job with every core simulating and the GPU learning, so a job may have more
rollout workers here than the 4 a racer may ask for (``MAX_WORKERS``; ``round_models`` sets the
count on the models past model_create's check, a benchmark's licence only). A rollout worker
steps its cars in one sandbox child, so it keeps one core busy; each job keeps one more for its
trainer, which reads, decodes and feeds the GPU the episodes while its workers drive: a job gets
``(cores - jobs) // jobs`` workers, at least 1 (on the 16-core device machine 15 for one job, 7
each for 2, 3 for 4, 1 for 8; on the 2-core dev box 1). Its cars between them cover the
iteration's 20 episodes and no more (more would stand idle: a worker reserves no more episodes
of a version than the trainer still wants, rl.experience's reservations, the first to ask first):
``ceil(20 / workers)`` cars a worker, at most 8 (PITLANE_CARS_PER_WORKER's default). Where 20
does not divide, some stand idle: one job's 15 workers of 2 cars drive the 20 episodes on the 10
workers that reserve first (two cars a core, one batched forward pass a step), then wait with the
other 5 for the new weights; ``--cars 1`` drives 15 at once, then 5. What each round prints says
its cores: simulating (its jobs' workers) and feeding (its trainers) of the machine's. The
trainers learn while their workers wait for the new weights, on the GPU where PyTorch finds one
(each gets ``cores // jobs`` threads, PITLANE_TRAINER_THREADS' rule).

``--policy child`` keeps each rollout's policy in its sandbox child rather than the machine's
policy server; ``--update stub`` has the trainers learn nothing (``bench.pipeline_settings``:
each update republishes the weights it had), which shows the pipeline's ceiling without the
update: driving, transfer, saving and the checks alone.

Runs wherever the project's packages are: here on the CPU in a short form (``--minutes 2 --jobs
1``), on the device machine from the wheels scripts/device-bundle.sh fetches (the command it
prints); ``--redis-server`` names Redis's executable where it is not on the PATH.
"""

from __future__ import annotations

import argparse
import io
import math
import os
import sys
import tempfile
import time
from pathlib import Path

from bench.stack import add_policy_option, private_redis, sigterm_exits, started

EPISODES = 20  # DeepRacer's episodes between policy updates (num_episodes_between_training)
MAX_CARS = 8  # PITLANE_CARS_PER_WORKER's default
START_LIMIT = 240.0  # [s] for every job to be driving (workers load torch and the simulator)
STOP_LIMIT = 300.0  # [s] for every job to finish once stopped (its last checkpoint)
EARLY_SHOWN = 6  # the first job's iterations shown one by one: where an early one's time goes


def layout(cores: int, jobs: int, workers: int | None, cars: int | None) -> tuple[int, int]:
    """(rollout workers per job, cars per worker) for ``jobs`` at once on ``cores``: a core for
    each job's trainer, the rest simulating, shared equally; the module's docstring says why."""
    chosen = workers or max((cores - jobs) // jobs, 1)
    return chosen, cars or min(math.ceil(EPISODES / chosen), MAX_CARS)


def round_models(owner, jobs: int, workers: int) -> list:
    """``jobs`` models with DeepRacer's defaults, each of ``workers`` rollout workers, the count
    set past the ``MAX_WORKERS`` a racer may ask for (model_create's check) where the layout
    wants more. Made before the round's Celery workers start: their trainer tasks wait in the
    broker until then, so no trainer reads a model before its count is set."""
    from bench.bench_training import default_model
    from training.configuration import MAX_WORKERS

    models = []
    for n in range(jobs):
        model = default_model(owner, f"pipeline-{jobs}-{n}", workers=min(workers, MAX_WORKERS))
        model.workers = workers
        model.save(update_fields=["workers"])
        models.append(model)
    return models


def worker_commands(jobs: int, workers: int) -> dict[str, list[str]]:
    """The Celery workers of one round: a trainer process per job, a simulation process per
    rollout worker; no re-scoring worker, no scheduler."""
    from console.supervisor import worker_pools

    pools = worker_pools(trainers=jobs, simulations=jobs * workers, prefix=f"bench{jobs}-")
    return {
        pool.queue: pool.command() for pool in pools if pool.queue in ("training", "simulation")
    }


def wait_for(what: str, done, limit: float, log_dir: Path) -> None:
    """Poll ``done()`` every second until it holds; past ``limit`` seconds, end the benchmark
    with the end of each worker's log."""
    deadline = time.monotonic() + limit
    while not done():
        if time.monotonic() > deadline:
            for log in sorted(log_dir.glob("*.log")):
                print(f"--- the end of {log.name}:\n{log.read_text(errors='replace')[-3000:]}")
            sys.exit(f"Gave up waiting {limit:.0f} s for {what}.")
        time.sleep(1)


def train_round(models: list, minutes: float) -> list:
    """Let ``models`` train ``minutes`` once all drive, stop them and wait for their ends; their
    jobs."""
    from bench.bench_training import job_of
    from training.models import TrainingJob
    from training.services import training_stop

    jobs = len(models)
    log_dir = Path(os.environ["PITLANE_VAR_DIR"])

    def statuses() -> list[str]:
        return [job_of(model).status for model in models]

    def failed() -> None:
        for model in models:
            job = job_of(model)
            if job.status == TrainingJob.Status.FAILED:
                sys.exit(f"Job {job.pk} failed: {job.failure_reason}")

    wait_for(
        f"{jobs} job(s) to drive",
        lambda: failed() or all(s == TrainingJob.Status.IN_PROGRESS for s in statuses()),
        START_LIMIT,
        log_dir,
    )
    time.sleep(minutes * 60)
    for model in models:
        training_stop(job=job_of(model))
    wait_for(
        f"{jobs} job(s) to stop",
        lambda: not any(job_of(model).is_active for model in models),
        STOP_LIMIT,
        log_dir,
    )
    return [job_of(model) for model in models]


def report(jobs: list) -> None:
    """Per job: iterations, steps, sustained steps/s and the share of each phase of the wall time;
    then the jobs' steps/s together."""
    from rl.stopwatch import PHASES
    from training.models import Iteration

    print(
        "  job  status     iters  steps  wall s  steps/s  " + "  ".join(f"{p:>9}" for p in PHASES)
    )
    total = 0.0
    for job in jobs:
        rows = list(Iteration.objects.filter(job=job))
        if not rows:
            print(
                f"  {job.pk:3d}  {job.status:9s}  no iteration ended ({job.episodes} episodes "
                f"arrived): give it more --minutes"
            )
            continue
        steps, wall = sum(r.steps for r in rows), sum(r.wall_seconds for r in rows)
        rate = steps / wall
        total += rate
        split = {p: sum(r.time_split.get(p, 0.0) for r in rows) for p in PHASES}
        shares = "  ".join(f"{100 * split[p] / wall:8.1f}%" for p in PHASES)
        print(
            f"  {job.pk:3d}  {job.status:9s}  {len(rows):5d}  {steps:5d}  {wall:6.1f}  "
            f"{rate:7.1f}  {shares}"
        )
    print(f"  all {len(jobs)} job(s): {total:.1f} steps/s", flush=True)
    first = Iteration.objects.filter(job=jobs[0]).order_by("number")[:EARLY_SHOWN]
    print(f"  job {jobs[0].pk}'s first iterations, seconds: " + ", ".join(PHASES), flush=True)
    for row in first:
        split = ", ".join(f"{row.time_split.get(p, 0.0):.1f}" for p in PHASES)
        print(f"    {row.number:3d}: {row.steps:5d} steps in {row.wall_seconds:6.1f} s ({split})")


def machine_words() -> str:
    import torch

    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "no GPU"
    return (
        f"{os.cpu_count()} cores, {gpu}, PyTorch {torch.__version__}, "
        f"Python {sys.version.split()[0]}"
    )


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--jobs", type=int, nargs="+", default=[1], help="jobs at once, in turn")
    parser.add_argument("--minutes", type=float, default=5.0, help="[min] of training per round")
    parser.add_argument("--workers", type=int, default=None, help="rollout workers per job")
    parser.add_argument("--cars", type=int, default=None, help="cars per rollout worker")
    parser.add_argument("--redis-server", default=None, help="Redis's executable")
    add_policy_option(parser)
    parser.add_argument(
        "--update",
        default="real",
        choices=("real", "stub"),
        help="stub: the trainers learn nothing, republishing their weights (the ceiling)",
    )
    chosen = parser.parse_args()
    if any(jobs < 1 for jobs in chosen.jobs):
        parser.error("--jobs takes counts of 1 or more")
    if chosen.workers is not None and chosen.workers < 1:
        parser.error("--workers takes a count of 1 or more")
    if chosen.cars is not None and not 1 <= chosen.cars <= 64:
        parser.error("--cars takes 1 to 64 (PITLANE_CARS_PER_WORKER's range)")
    return chosen


def rounds(chosen: argparse.Namespace, var_dir: str, redis_url: str) -> None:
    """Set the database up, then train each round of ``chosen.jobs`` and report it."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJANGO_")}
    env.update(
        DJANGO_SETTINGS_MODULE="bench.pipeline_settings",
        PITLANE_VAR_DIR=var_dir,
        REDIS_URL=redis_url,
        PYTHONUNBUFFERED="1",
        PITLANE_ROLLOUT_DEVICE=chosen.policy,
        PITLANE_BENCH_UPDATE=chosen.update,
    )
    os.environ.update(env)
    import django
    from django.core.management import call_command

    django.setup()
    call_command("migrate", interactive=False, verbosity=0)
    call_command("loadtracks", stdout=io.StringIO())
    from bench.bench_training import bench_racer

    owner = bench_racer()
    print(f"Training throughput without the web tier, DeepRacer's defaults: {machine_words()}")
    stub = ", the update stubbed out (nothing learnt)" if chosen.update == "stub" else ""
    print(f"The cars' policy: PITLANE_ROLLOUT_DEVICE={chosen.policy}{stub}")
    cores = os.cpu_count() or 1
    for jobs in chosen.jobs:
        workers, cars = layout(cores, jobs, chosen.workers, chosen.cars)
        round_env = {**env, "PITLANE_CARS_PER_WORKER": str(cars), "PITLANE_TRAINERS": str(jobs)}
        os.environ.update(round_env)
        print(
            f"{jobs} job(s), each {workers} rollout worker(s) of {cars} car(s), "
            f"{chosen.minutes:g} min; cores: {jobs * workers} simulating, {jobs} feeding "
            f"the trainers, of {cores}:",
            flush=True,
        )
        models = round_models(owner, jobs, workers)
        with started(worker_commands(jobs, workers), round_env, var_dir):
            report(train_round(models, chosen.minutes))


def main() -> None:
    chosen = arguments()
    with (
        sigterm_exits(),  # ``timeout`` stops the workers too, as Ctrl-C does
        tempfile.TemporaryDirectory(prefix="pitlane-pipeline-") as var_dir,
        private_redis(var_dir, chosen.redis_server) as redis_url,
    ):
        rounds(chosen, var_dir, redis_url)


if __name__ == "__main__":
    main()
