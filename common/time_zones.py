"""Dates in the racer's time zone.

The browser names its IANA zone in a cookie (``static/console/time_zone.js`` sets it on every
page); each request then renders its dates in that zone. A page written before the cookie
existed (a racer's very first page) is relabelled in place by the same script, so no date is
ever shown in the server's zone to a racer who lives in another.
"""

from __future__ import annotations

import functools
import zoneinfo
from collections.abc import Callable
from datetime import datetime

from asgiref.sync import iscoroutinefunction, markcoroutinefunction
from django.http import HttpRequest, HttpResponse
from django.utils import dateformat, timezone

COOKIE = "pitlane_tz"
# How a moment is written; static/console/time_zone.js writes the same in the browser's zone.
FORMATS = {"datetime": "j M Y, H:i", "time": "H:i:s"}


@functools.cache
def _known() -> frozenset[str]:
    return frozenset(zoneinfo.available_timezones())


def zone_named(name: str | None) -> zoneinfo.ZoneInfo | None:
    """The zone a cookie names, if it is a real IANA zone (anything else is ignored)."""
    if not name or len(name) > 64 or name not in _known():
        return None
    return zoneinfo.ZoneInfo(name)


class TimeZoneMiddleware:
    """Activates the request's zone; sync and async, so that an async view (``training.checks``)
    is awaited on the server's event loop rather than run in one of its threads."""

    sync_capable = async_capable = True

    def __init__(self, get_response: Callable[[HttpRequest], HttpResponse]) -> None:
        self.get_response = get_response
        if iscoroutinefunction(get_response):
            markcoroutinefunction(self)

    def __call__(self, request: HttpRequest):
        if iscoroutinefunction(self):
            return self._acall(request)
        _activate(request)
        return self.get_response(request)

    async def _acall(self, request: HttpRequest) -> HttpResponse:
        _activate(request)
        return await self.get_response(request)


def _activate(request: HttpRequest) -> None:
    zone = zone_named(request.COOKIES.get(COOKIE))
    if zone is None:
        timezone.deactivate()
    else:
        timezone.activate(zone)


def local_text(moment: datetime, style: str = "datetime") -> str:
    """``moment`` as the racer reads it: in the zone this request is in, in a ``FORMATS`` style."""
    return dateformat.format(timezone.localtime(moment), FORMATS[style])


def time_zone(request: HttpRequest) -> dict:
    """Context: the zone this page's dates are written in, for the footer."""
    return {"time_zone_name": timezone.get_current_timezone_name()}
