"""How often a racer, or an address, may do what costs the console most.

Attempts are counted by django-ratelimit in the shared cache (Redis), so every web process on
every machine counts together, in fixed windows. An attempt over its rate is refused before any
work, with a sentence that says how long to wait (``over`` gives the ``Limited``); the views
answer 429 with it. An attempt whose outcome says which limit it counts against (an import) is
held against each at once (``hold``), and given back to the others once that is known.
The rates are settings (``PITLANE_RATES``, from environment variables; docs/operating.md, "Limits").
Every refusal says when to try again in a ``Retry-After`` header too, set in one place
(``RetryAfterMiddleware``) from the ``Limited`` the request was refused with.

Where the cache cannot be reached, signing in and signing up are refused for the moment (503,
``Unavailable``): those limits are what stands between a guesser and the racers' passwords, or a
script and a thousand accounts, so they fail closed. Other attempts are let through (the console
says so in its log): each is a signed-in racer's, bounded again by what it asks for (the checkers,
the queue, the sandbox), and refusing them would stop every racer's work for an outage of a cache.
"""

from __future__ import annotations

import logging
import math

from django.conf import settings
from django.core.cache import caches
from django.forms import BaseForm
from django.forms.utils import ErrorDict
from django.http import HttpRequest, HttpResponse
from django_ratelimit import core as ratelimit_core
from django_ratelimit.core import get_usage
from redis.exceptions import RedisError

from common.middleware import SyncAndAsyncMiddleware

logger = logging.getLogger(__name__)

# What each limit counts, in a racer's words: "Too many {what}."
WHAT = {
    "sign-in-account": "sign-in attempts for this racer",
    "sign-in-address": "sign-in attempts from your address",
    "sign-up": "new accounts from your address",
    "profile-password": "wrong current passwords on your profile",
    "validate": "reward function checks",
    "import": "imports",
    "import-refused": "refused or unconfirmed imports",
    "create": "new models",
    "evaluate": "evaluations and race entries",
    "rescore": "re-scorings",
    "password-reset": "password reset requests from your address",
    "password-reset-email": "password reset requests for that email address",
    "api": "API requests with this token",
}


# Limits that refuse attempts while they cannot be counted (the module's docstring).
FAIL_CLOSED = frozenset({"sign-in-account", "sign-in-address", "sign-up"})
UNAVAILABLE_RETRY = 10  # [s] when a refused sign-in or sign-up is asked to try again


class Limited(Exception):
    """Over a limit: the message says which and how long to wait (``wait``, in seconds)."""

    status = 429

    def __init__(self, action: str, wait: int) -> None:
        minutes = max(1, math.ceil(wait / 60))
        super().__init__(
            f"Too many {WHAT[action]} for now: try again in {minutes} minute"
            f"{'s' if minutes != 1 else ''}."
        )
        self.action, self.wait = action, wait


class Unavailable(Limited):
    """An attempt at a limit that fails closed (``FAIL_CLOSED``), which could not be counted."""

    status = 503

    def __init__(self, action: str) -> None:
        Exception.__init__(
            self,
            f"{'Signing up' if action == 'sign-up' else 'Signing in'} is paused for a moment "
            "while the console reconnects to its store: try again in a moment.",
        )
        self.action, self.wait = action, UNAVAILABLE_RETRY


def over(
    request: HttpRequest, action: str, key: str | None = None, *, every_method: bool = False
) -> Limited | None:
    """For a POST (any request with ``every_method``: the API's): count it as an attempt at
    ``action``, by ``key`` (the signed-in racer where None); the ``Limited`` when that is over
    the rate (or ``Unavailable``), else None (and for anything else)."""
    try:
        usage = _counted(request, action, key, every_method=every_method)
    except Unavailable as unavailable:
        return _refusing(request, unavailable)
    if usage is not None and usage["should_limit"]:
        return _refusing(request, Limited(action, usage["time_left"]))
    return None


class Held:
    """An attempt counted up front against several limits (``hold``), before its outcome says
    which of them it counts against: those it does not are given back (``give_back``)."""

    def __init__(self, counted: dict[str, str]) -> None:
        self._counted = counted  # action: the cache key of the window it was counted in
        self.limited: Limited | None = None

    def give_back(self, *actions: str) -> None:
        """Take this attempt off the counts of ``actions`` (in the window it was counted in:
        one since ended has nothing to give back)."""
        cache = caches[settings.RATELIMIT_USE_CACHE]
        for action in actions:
            cache_key = self._counted.pop(action, None)
            if cache_key is None:
                continue
            try:
                cache.decr(cache_key)
            except ValueError:  # the window ended, and its count with it
                pass
            except RedisError as error:
                logger.warning("Rate limit %s not given back: %s", action, error)


def hold(
    request: HttpRequest, *actions: str, key: str | None = None, keys: dict[str, str] | None = None
) -> Held:
    """For a POST: count it at once as an attempt at each of ``actions``, so that attempts made
    in parallel count each other before any outcome is known. ``limited``: the first of them it
    is over (or ``Unavailable``), the attempt then given back to all; else the caller gives it
    back, once its outcome is known, to those it does not count against (an import that arrives
    is not a refused one, a sign-in that succeeds not a failed one). Each action is counted by
    its key in ``keys``, else by ``key`` (the signed-in racer where None)."""
    held = Held({})
    if request.method != "POST":
        return held
    for action in actions:
        by = (keys or {}).get(action) or key or f"racer:{request.user.pk}"
        try:
            usage = _counted(request, action, by)
        except Unavailable as unavailable:
            held.limited = held.limited or _refusing(request, unavailable)
            break
        if usage is None:
            continue
        held._counted[action] = _cache_key(action, by)
        if usage["should_limit"] and held.limited is None:
            held.limited = _refusing(request, Limited(action, usage["time_left"]))
    if held.limited is not None:
        held.give_back(*actions)
    return held


def _cache_key(action: str, key: str) -> str:
    """django-ratelimit's key for the count of ``action`` by ``key`` in the present window, as
    ``get_usage`` makes it (django-ratelimit 4.1 core.py: it has no public way to give one back;
    tests/archives/test_import_archives.py's rate tests prove it is the counter's)."""
    rate = settings.PITLANE_RATES[action]
    window = ratelimit_core._get_window(key, ratelimit_core._split_rate(rate)[1])
    return ratelimit_core._make_cache_key(
        f"pitlane:{action}", window, rate, key, ratelimit_core.ALL
    )


def _counted(
    request: HttpRequest, action: str, key: str | None, *, every_method: bool = False
) -> dict | None:
    """Count a POST (any request, ``every_method``) as an attempt at ``action`` by ``key``;
    django-ratelimit's usage after it."""
    if request.method != "POST" and not every_method:
        return None
    if key is None:
        key = f"racer:{request.user.pk}"
    try:
        return get_usage(
            request,
            group=f"pitlane:{action}",
            key=lambda group, request: key,
            rate=settings.PITLANE_RATES[action],
            increment=True,
        )
    except RedisError as error:
        logger.warning("Rate limit %s not counted: %s", action, error)
        if action in FAIL_CLOSED:
            raise Unavailable(action) from error
        return None


def _refusing(request: HttpRequest, limited: Limited) -> Limited:
    """``limited``, noted on ``request`` for ``RetryAfterMiddleware``."""
    request.pitlane_limited = limited
    return limited


class RetryAfterMiddleware(SyncAndAsyncMiddleware):
    """Every refusal for a limit (429, or ``Unavailable``'s 503) says in ``Retry-After`` how many
    seconds to wait: here once, from the ``Limited`` noted on the request, not in each view."""

    def after(self, request: HttpRequest, response: HttpResponse) -> HttpResponse:
        limited = getattr(request, "pitlane_limited", None)
        if limited is not None and response.status_code == limited.status:
            response.setdefault("Retry-After", str(max(1, math.ceil(limited.wait))))
        return response


def refuse(form: BaseForm, limited: Limited) -> None:
    """Show ``limited`` as ``form``'s only error, without validating it: past a limit nothing is
    checked (a sign-in form would check the password), and what the racer typed stays."""
    form._errors = ErrorDict()
    form.cleaned_data = {}
    form.add_error(None, str(limited))


def address(request: HttpRequest) -> str:
    """The client's address, as the server saw it (behind a proxy: see docs/operating.md)."""
    return "address:" + request.META.get("REMOTE_ADDR", "")
