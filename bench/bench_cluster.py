"""One job on 1, 2 and 4 simulation machines, and 8 jobs at once: `python -m bench.bench_cluster`.

Starts the cluster of ``make cluster`` (``tests.cluster``: PostgreSQL, Redis, S3, a web machine,
one training machine serving one job at a time, simulation machines each running one worker
process), then, as an operator's script on the same settings, creates models with all of
DeepRacer's defaults (as ``bench_training`` does) and lets them train:

- ``--machines 1 2 4``: one job with one rollout worker per simulation machine, for
  ``--minutes``; its environment steps per second over the iterations it finished, the trainer's
  share of the wall time (the policy update and the saving, while the workers wait), and what
  the job moved through Redis per environment step (Redis's own byte counters, both ways, over
  the same iterations): the figure that sets how many jobs one Redis carries.
- ``--jobs 8``: that many jobs of one worker each, created at once, on ``--trainers`` training
  machines and ``--machines-for-jobs`` simulation machines, each job stopped after
  ``--job-minutes`` of training: how long each waited in the queue, and its steps per second
  while it trained.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from tests.cluster import Cluster


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", type=int, nargs="*", default=[1, 2, 4])
    parser.add_argument("--minutes", type=float, default=4.0, help="of training per run")
    parser.add_argument("--jobs", type=int, default=8)
    parser.add_argument("--job-minutes", type=float, default=1.5)
    parser.add_argument("--trainers", type=int, default=2, help="training machines")
    parser.add_argument("--machines-for-jobs", type=int, default=2)
    args = parser.parse_args()
    most = max([*args.machines, args.machines_for_jobs])
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-cluster-") as folder:
        cluster = Cluster(Path(folder), simulation=most, training=args.trainers, processes=1)
        try:
            cluster.start()
            _use(cluster)
            owner = _racer()
            print(
                f"1 web, {args.trainers} training and {most} simulation machines (one worker "
                f"process each) on {os.cpu_count()} cores; {args.minutes:g} min a run\n"
            )
            print("  sim machines  iterations  steps/s  trainer share  Redis bytes/step")
            for count in args.machines:
                _one_job(cluster, owner, count, args.minutes)
            if args.jobs:
                _many_jobs(owner, args.jobs, args.job_minutes)
        finally:
            cluster.stop()


def _use(cluster: Cluster) -> None:
    """Point this process's Django at the cluster, as a script on one of its machines."""
    os.environ.update(cluster.web.env)
    import django

    django.setup()


def _racer():
    from bench.bench_training import bench_racer

    return bench_racer()


def _wait_status(model, status: str) -> None:
    from bench.bench_training import job_of

    while job_of(model).status != status:
        time.sleep(1)


def _redis_bytes() -> int:
    from common.redis_client import redis_client

    stats = redis_client().info("stats")
    return stats["total_net_input_bytes"] + stats["total_net_output_bytes"]


def _one_job(cluster: Cluster, owner, machines: int, minutes: float) -> None:
    from bench.bench_training import default_model, job_of
    from rl.stopwatch import SAVING, UPDATE
    from training.models import Iteration
    from training.services import training_stop

    model = default_model(owner, f"machines-{machines}", workers=machines)
    _wait_status(model, "IN_PROGRESS")
    while not Iteration.objects.filter(job=job_of(model)).exists():  # the first, from a start
        time.sleep(0.5)
    before, first = _redis_bytes(), Iteration.objects.filter(job=job_of(model)).count()
    time.sleep(minutes * 60)
    moved = _redis_bytes() - before
    job = job_of(model)
    rows = list(Iteration.objects.filter(job=job).order_by("number"))[first:]
    training_stop(job=job)
    _wait_status(model, "COMPLETED")
    steps, wall = sum(r.steps for r in rows), sum(r.wall_seconds for r in rows)
    trainer = sum(r.time_split.get(UPDATE, 0) + r.time_split.get(SAVING, 0) for r in rows)
    if not wall:
        print(f"  {machines:12d}  no iteration finished in {minutes:g} min")
        return
    print(
        f"  {machines:12d}  {len(rows):10d}  {steps / wall:7.1f}  {trainer / wall:12.0%}  "
        f"{moved / max(steps, 1):16,.0f}",
        flush=True,
    )


def _many_jobs(owner, jobs: int, minutes: float) -> None:
    from bench.bench_training import default_model, job_of
    from training.models import Iteration
    from training.services import training_stop

    models = [default_model(owner, f"crowd-{n}") for n in range(jobs)]
    created = time.monotonic()
    began: dict[int, float] = {}
    ended: set[int] = set()
    while len(ended) < jobs:
        for model in models:
            job = job_of(model)
            if model.pk not in began and job.status == "IN_PROGRESS":
                began[model.pk] = time.monotonic()
            elif model.pk in began and model.pk not in ended:
                if job.status == "COMPLETED":
                    ended.add(model.pk)
                elif job.is_active and time.monotonic() - began[model.pk] > minutes * 60:
                    training_stop(job=job)
        time.sleep(1)
    print(
        f"\n{jobs} jobs of one worker created at once, stopped after {minutes:g} min of "
        "training each:"
    )
    print("  job  queued for  iterations  steps/s")
    for n, model in enumerate(models):
        rows = list(Iteration.objects.filter(job=job_of(model)))
        wall = sum(r.wall_seconds for r in rows)
        rate = f"{sum(r.steps for r in rows) / wall:7.1f}" if wall else "      —"
        queued = (began[model.pk] - created) / 60
        print(f"  {n:3d}  {queued:6.1f} min  {len(rows):10d}  {rate}", flush=True)


if __name__ == "__main__":
    main()
