"""bench.bench_pipeline's layout: one job can have every core but its trainer's simulating, more
rollout workers than a racer may ask for."""

from bench.bench_pipeline import layout, round_models
from bench.bench_training import bench_racer
from training.configuration import MAX_WORKERS


def test_one_job_simulates_on_every_core_but_the_one_feeding_its_trainer():
    # (jobs): (rollout workers a job, cars a worker) on the device machine's 16 cores
    laid_out = {jobs: layout(16, jobs, None, None) for jobs in (1, 2, 3, 4, 8)}
    assert laid_out == {1: (15, 2), 2: (7, 3), 3: (4, 5), 4: (3, 7), 8: (1, 8)}
    assert layout(2, 1, None, None) == (1, 8)  # the dev box; 8 cars: PITLANE_CARS_PER_WORKER's
    assert layout(64, 64, None, None) == (1, 8)  # at least one worker a job
    assert layout(16, 1, 6, 3) == (6, 3)  # as --workers and --cars say


def test_a_rounds_models_have_the_workers_the_layout_gives_past_what_a_racer_may_ask(tracks):
    (model,) = round_models(bench_racer(), 1, MAX_WORKERS + 11)
    model.refresh_from_db()
    assert model.workers == MAX_WORKERS + 11
