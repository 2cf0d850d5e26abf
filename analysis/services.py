"""What a racer may change from the analysis: asking for a re-scoring."""

from __future__ import annotations

from datetime import timedelta

from django.contrib.auth import get_user_model
from django.db import transaction
from django.utils import timezone

from analysis import lifecycle
from analysis.models import Rescoring
from analysis.records import Source
from common import queueing
from common.refusals import Refused

MAX_RESCORE_STEPS = 200_000  # recorded steps one re-scoring may score (about a minute of work)
MAX_RESCORINGS_AT_ONCE = 3  # a racer's re-scorings waiting or running
LAPSE_MARGIN = 60  # [s] past the task's hard time limit before a running re-scoring is dead
_R = Rescoring.Status
RESCORE = "analysis.rescore"  # the task that runs a re-scoring (analysis.tasks), queued by name


class RescoringRefused(Refused):
    """The re-scoring was not asked for; ``errors`` says why, per input."""


def rescoring_create(
    *, source: Source, owner, reward_function: str, first: int | None, last: int | None
) -> Rescoring:
    """Ask for ``reward_function`` to be run over ``source``'s recorded steps, iterations
    ``first``..``last`` (by default the latest that fit in MAX_RESCORE_STEPS)."""
    steps = dict(source.summaries().values_list("iteration", "steps"))
    if not steps:
        raise RescoringRefused("There is no recorded driving to score yet.")
    first, last = _range(steps, first, last)
    total = sum(count for iteration, count in steps.items() if first <= iteration <= last)
    if total > MAX_RESCORE_STEPS:
        raise RescoringRefused(
            {
                "first": f"Iterations {first} to {last} hold {total:,} steps; a re-scoring "
                f"takes at most {MAX_RESCORE_STEPS:,}. Choose fewer iterations."
            }
        )
    rescorings_lapsed(owner=owner)
    with transaction.atomic():
        # One request at a time per racer counts and adds (PostgreSQL locks the racer's row).
        get_user_model().objects.select_for_update().filter(pk=owner.pk).first()
        busy = Rescoring.objects.filter(owner=owner, status__in=(_R.QUEUED, _R.RUNNING))
        if busy.count() >= MAX_RESCORINGS_AT_ONCE:
            raise RescoringRefused("Wait for your re-scorings running now to finish.")
        rescoring = Rescoring.objects.create(
            owner=owner,
            job=source.job,
            evaluation=source.evaluation,
            reward_function=reward_function,
            first=first,
            last=last,
            total_steps=total,
        )
    transaction.on_commit(lambda: queueing.enqueue(RESCORE, rescoring.pk))
    return rescoring


def rescorings_lapsed(*, owner) -> int:
    """Fail ``owner``'s re-scorings whose worker died: running for longer than the task may
    (its hard time limit would have stopped it), so no run will ever end them; how many."""
    from analysis.tasks import RESCORE_HARD_LIMIT

    since = timezone.now() - timedelta(seconds=RESCORE_HARD_LIMIT + LAPSE_MARGIN)
    lapsed = Rescoring.objects.filter(owner=owner, status=_R.RUNNING, started_at__lt=since)
    failed = 0
    for pk in lapsed.values_list("pk", flat=True):
        failed += lifecycle.RESCORING.move(
            pk,
            _R.FAILED,
            only_from={_R.RUNNING},
            finished_at=timezone.now(),
            failure="The worker scoring it stopped answering; ask for it again.",
        )
    return failed


def _range(steps: dict[int, int], first: int | None, last: int | None) -> tuple[int, int]:
    known = sorted(steps)
    if first is not None and last is not None and first > last:
        raise RescoringRefused({"last": "The last iteration comes before the first."})
    if last is None:
        last = max(known[-1], first or 0)
    if first is None:  # the latest iterations that fit
        first, total = last, 0
        for iteration in reversed([i for i in known if i <= last]):
            total += steps[iteration]
            if total > MAX_RESCORE_STEPS:
                break
            first = iteration
    if not any(first <= iteration <= last for iteration in known):
        raise RescoringRefused(
            {
                "first": f"No iteration from {first} to {last} was recorded; iterations "
                f"{known[0]} to {known[-1]} were."
            }
        )
    return max(first, known[0]), min(last, known[-1])  # what was recorded of first..last
