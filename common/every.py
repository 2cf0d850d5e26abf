"""Work done every so often inside a loop: a lease renewed, a stop looked for, workers checked."""

from __future__ import annotations

import math
import time


class Every:
    """Says when ``seconds`` have passed since it last said so: the first time at once, or,
    ``at_once=False``, ``seconds`` after it was made."""

    def __init__(self, seconds: float, *, at_once: bool = True) -> None:
        self.seconds = seconds
        self._last = -math.inf if at_once else time.monotonic()

    def due(self) -> bool:
        now = time.monotonic()
        if now - self._last < self.seconds:
            return False
        self._last = now
        return True
