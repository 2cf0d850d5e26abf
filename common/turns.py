"""Racers take turns at work that is shared: the rule of the reward checkers (training.checkers)
and of the re-scoring workers (analysis.selectors.rescorings_in_turn), written once.

The next piece of work is that of the waiting racer who has the fewest running; among them, the
one whose last piece started longest ago (``served``; a racer with none remembered, 0, goes
first); among those, the one who came first (``came``). A racer with nothing running is therefore
served before anyone who was served lately, and one racer's line of work holds another's for at
most one piece each.
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable, Mapping, Sequence
from typing import TypeVar

K = TypeVar("K", bound=Hashable)
T = TypeVar("T")


def next_racer(
    waiting: Sequence[K],
    *,
    running: Mapping[K, int],
    served: Mapping[K, float],
    came: Mapping[K, float],
) -> K:
    """Whose work goes next among the racers ``waiting`` (the module's rule)."""
    return min(
        waiting, key=lambda racer: (running.get(racer, 0), served.get(racer, 0.0), came[racer])
    )


def in_turn(
    queues: Mapping[K, Sequence[T]],
    *,
    running: Mapping[K, int],
    served: Mapping[K, float],
    came: Mapping[K, float],
) -> list[T]:
    """Every piece of work in ``queues`` (each racer's, first come first) in the order it will be
    taken up, each racer counted as served when their piece is taken (after every time given)."""
    heads = {racer: 0 for racer, queue in queues.items() if queue}
    served = dict(served)
    after = itertools.count(max(served.values(), default=0.0) + 1)
    order: list[T] = []
    while heads:
        racer = next_racer(list(heads), running=running, served=served, came=came)
        order.append(queues[racer][heads[racer]])
        heads[racer] += 1
        if heads[racer] == len(queues[racer]):
            del heads[racer]
        served[racer] = next(after)
    return order
