"""How often a racer, or an address, may do what costs the console most.

Attempts are counted by django-ratelimit in the shared cache (Redis), so every web process on
every machine counts together, in fixed windows. An attempt over its rate is refused before any
work, with a sentence that says how long to wait (``over`` gives the ``Limited``); the views
answer 429 with it.
The rates are settings (``PITLANE_RATES``, from environment variables; README, "Limits").
Where the cache cannot be reached, attempts are let through: the console says so in its log and
goes on, as it does for what else Redis holds.
"""

from __future__ import annotations

import logging
import math

from django.conf import settings
from django.forms import BaseForm
from django.forms.utils import ErrorDict
from django.http import HttpRequest
from django_ratelimit.core import get_usage
from redis.exceptions import RedisError

logger = logging.getLogger(__name__)

# What each limit counts, in a racer's words: "Too many {what}."
WHAT = {
    "sign-in-account": "sign-in attempts for this racer",
    "sign-in-address": "sign-in attempts from your address",
    "sign-up": "new accounts from your address",
    "validate": "reward function checks",
    "import": "imports",
    "import-refused": "refused or unconfirmed imports",
    "create": "new models",
    "evaluate": "evaluations and race entries",
    "rescore": "re-scorings",
    "password-reset": "password reset requests from your address",
    "password-reset-email": "password reset requests for that email address",
}


class Limited(Exception):
    """Over a limit: the message says which and how long to wait."""

    def __init__(self, action: str, wait: int) -> None:
        minutes = max(1, math.ceil(wait / 60))
        super().__init__(
            f"Too many {WHAT[action]} for now: try again in {minutes} minute"
            f"{'s' if minutes != 1 else ''}."
        )
        self.action, self.wait = action, wait


def over(request: HttpRequest, action: str, key: str | None = None) -> Limited | None:
    """For a POST: count it as an attempt at ``action``, by ``key`` (the signed-in racer where
    None); the ``Limited`` when that is over the rate, else None (and for anything else)."""
    usage = _usage(request, action, key, increment=True)
    if usage is not None and usage["should_limit"]:
        return Limited(action, usage["time_left"])
    return None


def reached(request: HttpRequest, action: str, key: str | None = None) -> Limited | None:
    """For a POST: the ``Limited`` when the attempts at ``action`` counted so far (``count``)
    fill its rate, so that one more would be over it; this one is not counted. For an action
    counted by its outcome (an import counts only when it arrives), once that is known."""
    usage = _usage(request, action, key, increment=False)
    if usage is not None and usage["count"] >= usage["limit"]:
        return Limited(action, usage["time_left"])
    return None


def count(request: HttpRequest, action: str, key: str | None = None) -> None:
    """For a POST: count it as an attempt at ``action`` (which ``reached`` checked before)."""
    _usage(request, action, key, increment=True)


def _usage(request: HttpRequest, action: str, key: str | None, *, increment: bool) -> dict | None:
    if request.method != "POST":
        return None
    if key is None:
        key = f"racer:{request.user.pk}"
    try:
        return get_usage(
            request, group=f"pitlane:{action}", key=lambda group, request: key,
            rate=settings.PITLANE_RATES[action], increment=increment,
        )  # fmt: skip
    except RedisError as error:
        logger.warning("Rate limit %s not counted: %s", action, error)
        return None


def refuse(form: BaseForm, limited: Limited) -> None:
    """Show ``limited`` as ``form``'s only error, without validating it: past a limit nothing is
    checked (a sign-in form would check the password), and what the racer typed stays."""
    form._errors = ErrorDict()
    form.cleaned_data = {}
    form.add_error(None, str(limited))


def address(request: HttpRequest) -> str:
    """The client's address, as the server saw it (behind a proxy: see the README)."""
    return "address:" + request.META.get("REMOTE_ADDR", "")
