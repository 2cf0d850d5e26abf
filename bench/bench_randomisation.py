"""Domain randomisation's figure: `python -m bench.bench_randomisation [--minutes M] [--trials N]`.

Starts the whole console as bench_training does (its Redis, a Celery worker, the database in a
scratch directory) and trains two models as its --qualify does (``default_model``: DeepRacer's
defaults on the Rookie Loop; with --fast, its racer's model), alike but for domain randomisation,
one after the other, each for ``--minutes`` of training. Then each model's best checkpoint (what
DeepRacer races and downloads) drives ``--trials`` one-lap trials in randomised scenes and as many
in the plain scene, each trial from its own seed (its scene, and Gazebo's noise: the same seed
gives the same trial), ending at the first reset as DeepRacer's evaluation does with no resets
allowed. The table: per model and scene, the trials that completed the lap and their mean
completion (progress when the trial ended).

A tiny run, to see it work: `python -m bench.bench_randomisation --minutes 1 --trials 3`.
"""

from __future__ import annotations

import argparse
import os
import time

from bench.bench_training import bench_racer, default_model, job_of
from bench.stack import running_console

SCENES = ("plain", "randomised")


def train(owner, *, randomise: bool, minutes: float, seed: int, fast: bool):
    """A model trained for ``minutes`` of its job's clock, then stopped; the model."""
    from training.services import training_stop

    name = f"{'randomised' if randomise else 'plain'}-{seed}{'-fast' if fast else ''}"
    model = default_model(owner, name, seed=seed, fast=fast, randomise=randomise)
    while (job := job_of(model)).training_seconds < minutes * 60 or not job.best_checkpoint:
        if job.status not in job.ACTIVE:
            raise SystemExit(f"{name}'s training ended early: {job.status} {job.message}")
        time.sleep(2)
    training_stop(job=job)
    while (job := job_of(model)).status in job.ACTIVE:
        time.sleep(1)
    print(f"  {name}: {job.training_seconds / 60:.1f} min, {job.iterations} iterations", flush=True)
    return model


def completion(model, *, randomise: bool, trials: int) -> tuple[int, float]:
    """(laps completed, mean completion %) of ``trials`` one-lap trials of the model's best
    checkpoint, each from its seed, in randomised scenes or the plain one."""
    import gymnasium

    import simulator
    from rl.learner import Learner
    from training import artifacts

    settings = {**model.environment_settings(), "randomise": randomise}
    env = gymnasium.make(
        simulator.ENV_ID, mode="evaluation", laps=1, max_resets=0, noise=True, **settings
    )
    learner = Learner.for_model(model, env)
    learner.restore(artifacts.read(job_of(model).best_checkpoint))
    laps, progress = 0, []
    for seed in range(trials):
        observation, _ = env.reset(seed=1_000 + seed)
        while True:
            action, _ = learner.model.policy.predict(observation, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
        laps += len(info["lap_times"])
        progress.append(100.0 if info["lap_times"] else info["progress"])
    env.close()
    return laps, sum(progress) / len(progress)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=20.0, help="training minutes a model")
    parser.add_argument("--trials", type=int, default=20, help="trials a model and scene")
    parser.add_argument("--seed", type=int, default=0, help="the models' training seed")
    parser.add_argument("--fast", action="store_true", help="bench_training's racer's model")
    arguments = parser.parse_args()
    with running_console(concurrency=3) as console:
        os.environ.update(console["env"])
        import django

        django.setup()
        owner = bench_racer()
        # flushed: a reward function's check forks a child, which would print it again
        print(
            f"Training two models, {arguments.minutes:g} min each (seed {arguments.seed}):",
            flush=True,
        )
        models = {
            trained: train(
                owner,
                randomise=trained == "randomised",
                minutes=arguments.minutes,
                seed=arguments.seed,
                fast=arguments.fast,
            )
            for trained in SCENES
        }
        print(
            f"\nEach model's best checkpoint, {arguments.trials} one-lap trials a scene "
            "(ended at the first reset):"
        )
        print(f"{'trained in':<22}{'evaluated in':<22}{'laps completed':>16}{'completion':>12}")
        for trained, model in models.items():
            for scene in SCENES:
                laps, mean = completion(
                    model, randomise=scene == "randomised", trials=arguments.trials
                )
                shown = f"{laps} of {arguments.trials}"
                print(
                    f"{trained + ' scenes':<22}{scene + ' scenes':<22}{shown:>16}{mean:>11.1f}%",
                    flush=True,
                )


if __name__ == "__main__":
    main()
