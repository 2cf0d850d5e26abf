"""Numbers from what someone else sent: a racer's form or settings, a sandbox child's frame."""

from __future__ import annotations

import math


def finite(value) -> float | None:
    """``value`` (a number, or the text of one) as a finite float; None when it is not one."""
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return number if math.isfinite(number) else None
