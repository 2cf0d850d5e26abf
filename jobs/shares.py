"""Each training's share of the machine (issue 56): equal, unless staff weight a racer.

A racer's share (``Quota.machine_share``, 1 unless staff set more in the admin) weighs each of
their trainings against the others training at the same time, in both places a training takes
the cores: its trainer's PyTorch threads at each update (``share_cores``) and its rollout
workers' sandbox children, the cars' simulation and reward function (``rollout_niceness``: a
lighter job's cars run at a higher niceness, so Linux's scheduler gives the heavier ones their
weight's part of a busy core; an idle core still goes to whoever wants it). The policy server,
the cars' shared inference, serves every job in turn whatever its share: a pass is short and one
waiting for another is what batching saves.
"""

from __future__ import annotations

import math
import os

from django.conf import settings

from training import leases
from training.models import TrainingJob

# Linux's CFS weighs a task 1.25 times the next niceness up (kernel/sched/core.c's
# sched_prio_to_weight: 1024 at 0, 820 at 1, ... 335 at 5), so a share half another's is about
# niceness 3 and a quarter's 6.
NICENESS_STEP = 1.25
MOST_NICENESS = 19


def share_cores(job_id: int) -> None:
    """Before each update, this trainer's PyTorch threads: the machine's cores shared among the
    jobs training now by their shares, ``PITLANE_TRAINER_THREADS`` at most. A job alone learns on
    every core (a share fixed by the trainers the machine could run gave it one of two: 35.9
    steps/s over 20 minutes against 62.9), and six learn on one each rather than spin on each
    other's (two trainers with every core each were several times slower than with half each).
    Jobs counted are the console's: on several training machines a trainer takes less than its
    machine's share, never more."""
    import torch

    training = TrainingJob.objects.filter(status=TrainingJob.Status.IN_PROGRESS)
    shares = leases.machine_shares(training)
    mine = shares.pop(job_id, 1)
    threads = cores_shared(
        len(os.sched_getaffinity(0)),
        share=mine,
        shares=mine + sum(shares.values()),
        most=settings.PITLANE_TRAINER_THREADS,
    )
    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)


def cores_shared(cores: int, *, share: int, shares: int, most: int) -> int:
    """A trainer's threads: its ``share`` of ``cores`` among ``shares`` (its own among them),
    ``most`` at most, one at least."""
    return max(1, min(most, cores * share // max(shares, share, 1)))


def rollout_niceness(job_id: int) -> int:
    """How much nicer than its worker a job's sandbox children run: 0 for the heaviest share
    among the jobs holding trainers, more for a lighter one by the ratio of their shares."""
    shares = leases.machine_shares(leases.jobs_holding_trainers())
    mine = shares.get(job_id, 1)
    return niceness_for(mine, heaviest=max([mine, *shares.values()]))


def niceness_for(share: int, *, heaviest: int) -> int:
    """The niceness at which a task gets ``share`` of what one of the ``heaviest`` share gets."""
    ratio = heaviest / max(share, 1)
    return min(MOST_NICENESS, max(0, round(math.log(ratio) / math.log(NICENESS_STEP))))
