"""What a racer may change from the analysis: asking for a re-scoring."""

from __future__ import annotations

from django.db import transaction

from analysis.models import Rescoring
from analysis.records import Source
from common.refusals import Refused

MAX_RESCORE_STEPS = 200_000  # recorded steps one re-scoring may score (about a minute of work)
MAX_RESCORINGS_AT_ONCE = 3  # a racer's re-scorings waiting or running


class RescoringRefused(Refused):
    """The re-scoring was not asked for; ``errors`` says why, per input."""


def rescoring_create(*, source: Source, owner, reward_function: str, first: int | None,
                     last: int | None) -> Rescoring:  # fmt: skip
    """Ask for ``reward_function`` to be run over ``source``'s recorded steps, iterations
    ``first``..``last`` (by default the latest that fit in MAX_RESCORE_STEPS)."""
    steps = dict(source.summaries().values_list("iteration", "steps"))
    if not steps:
        raise RescoringRefused("There is no recorded driving to score yet.")
    busy = Rescoring.objects.filter(owner=owner, status__in=(Rescoring.Status.QUEUED,
                                                            Rescoring.Status.RUNNING))  # fmt: skip
    if busy.count() >= MAX_RESCORINGS_AT_ONCE:
        raise RescoringRefused("Wait for your re-scorings running now to finish.")
    first, last = _range(steps, first, last)
    total = sum(count for iteration, count in steps.items() if first <= iteration <= last)
    if total > MAX_RESCORE_STEPS:
        raise RescoringRefused({
            "first": f"Iterations {first} to {last} hold {total:,} steps; a re-scoring takes at "
            f"most {MAX_RESCORE_STEPS:,}. Choose fewer iterations."
        })  # fmt: skip
    rescoring = Rescoring.objects.create(
        owner=owner, job=source.job, evaluation=source.evaluation,
        reward_function=reward_function, first=first, last=last, total_steps=total,
    )  # fmt: skip
    transaction.on_commit(lambda: _enqueue(rescoring.pk))
    return rescoring


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
        raise RescoringRefused({
            "first": f"No iteration from {first} to {last} was recorded; iterations "
            f"{known[0]} to {known[-1]} were."
        })  # fmt: skip
    return first, last


def _enqueue(pk: int) -> None:
    from analysis.tasks import rescore

    rescore.delay(pk)
