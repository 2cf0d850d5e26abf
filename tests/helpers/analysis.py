"""A trace written by hand and recorded as a training job's, a model whose job has no files, and
a reward function to score the trace with again."""

from __future__ import annotations

import shutil

from django.conf import settings as django_settings

from rl import hyperparameters
from simulator.trace import SimTraceRow, to_csv
from training import artifacts, configuration, signals
from training.models import RLModel, TrainingJob
from training.rewards import EXAMPLES


def row(episode, steps, x, y, steer, speed, action, reward, progress, waypoint, tstamp, status):
    """A trace row on the Pitlane Oval, with what follows from the rest filled in."""
    return SimTraceRow(
        episode=episode,
        steps=float(steps),
        X=x,
        Y=y,
        yaw=90.0,
        steer=steer,
        throttle=speed,
        action=action,
        reward=reward,
        done=status not in ("prepare", "in_progress"),
        all_wheels_on_track=status != "off_track",
        progress=progress,
        closest_waypoint=waypoint,
        track_len=16.5,
        tstamp=tstamp,
        episode_status=status,
        pause_duration=0.0,
        obstacle_crash_counter=0,
        wall_clock=1_700_000_000.0,
    )


# Two episodes on the Pitlane Oval (111 waypoints: a tenth of the lap is 11 of them). The first
# laps in three steps, the second leaves the track at its second step.
HAND_WRITTEN = [
    row(0, 1, 0.0, -1.49, 0.0, 0.0, -1, 0.0, 0.0, 0, 10.0, "prepare"),
    row(0, 2, 0.2, -1.49, -30.0, 1.0, 0, 1.0, 30.0, 0, 10.0667, "in_progress"),
    row(0, 3, 1.0, 1.49, 0.0, 2.0, 2, 2.0, 60.0, 55, 10.1333, "in_progress"),
    row(0, 4, -0.2, -1.49, 0.0, 2.0, 2, 3.0, 100.0, 109, 10.2, "lap_complete"),
    row(1, 1, 0.5, -1.49, 0.0, 0.0, -1, 0.0, 0.0, 5, 10.2, "prepare"),
    row(1, 2, 0.6, -1.49, 15.0, 0.5, 1, 0.5, 2.0, 5, 10.2667, "in_progress"),
    row(1, 3, 1.5, 2.5, 15.0, 0.5, 1, 0.001, 3.5, 6, 10.3333, "off_track"),
]


def untrained(owner, name: str) -> RLModel:
    """A model with a job and no files (no weights either: the analysis never reads them)."""
    settings = {
        "name": name,
        "track": "pitlane-oval",
        "reward_function": EXAMPLES[0].source,
        "hyperparameters": hyperparameters.defaults("clipped_ppo"),
    }
    clean = configuration.check(settings, owner=owner, validate_reward=False)
    model = RLModel.objects.create(owner=owner, status=RLModel.Status.READY, **clean.row())
    TrainingJob.objects.create(model=model, status=TrainingJob.Status.COMPLETED, iterations=1)
    shutil.rmtree(django_settings.MEDIA_ROOT / "models" / str(model.pk), ignore_errors=True)
    return model


def recorded_by_hand(owner) -> TrainingJob:
    """The job of a model of ``owner``'s that recorded ``HAND_WRITTEN`` as its first iteration."""
    model = untrained(owner, "by-hand")
    job = model.jobs.get()
    document = to_csv(HAND_WRITTEN)
    artifacts.save(model, artifacts.training_trace(1), document)
    signals.trace_recorded.send(TrainingJob, document=document, job=job, iteration=1)
    return job


# Twice the speed, and 100 for a step off the track: read from the replayed params.
SPEED_AND_OFF_TRACK = """
def reward_function(params):
    if params["steps"] == 2:
        print("waypoints:", len(params["waypoints"]))
    return 2.0 * params["speed"] + (100.0 if params["is_offtrack"] else 0.0)
"""
