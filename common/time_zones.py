"""Dates in the racer's time zone.

The browser names its IANA zone in a cookie (``static/console/time_zone.js`` sets it on every
page); each request then renders its dates in that zone. A page written before the cookie
existed (a racer's very first page) is relabelled in place by the same script, so no date is
ever shown in the server's zone to a racer who lives in another.
"""

from __future__ import annotations

import functools
import zoneinfo
from datetime import datetime

from django.http import HttpRequest
from django.utils import dateformat, timezone

from common.middleware import SyncAndAsyncMiddleware

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


class TimeZoneMiddleware(SyncAndAsyncMiddleware):
    """Activates the request's zone."""

    def before(self, request: HttpRequest) -> None:
        _activate(request)


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
