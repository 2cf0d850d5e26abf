"""Template tags and filters used across the site."""

from datetime import datetime

from django import template
from django.utils.html import format_html

from console.time_zones import local_text

register = template.Library()


@register.simple_tag
def when(moment: datetime | None, style: str = "datetime") -> str:
    """A moment in the racer's time zone (see console.time_zones), as a ``<time>`` element the
    browser can relabel: ``{% when job.created_at %}`` or ``{% when line.at "time" %}``."""
    if moment is None:
        return "—"
    return format_html(
        '<time datetime="{}" data-when="{}">{}</time>',
        moment.isoformat(), style, local_text(moment, style),
    )  # fmt: skip


@register.filter
def laptime(milliseconds: int | float | None) -> str:
    """A time in milliseconds as DeepRacer shows it: M:SS.mmm (``None`` shows as a dash)."""
    if milliseconds is None or milliseconds == "":
        return "—"
    total = round(float(milliseconds))
    minutes, rest = divmod(total, 60_000)
    seconds, millis = divmod(rest, 1000)
    return f"{minutes}:{seconds:02d}.{millis:03d}"


@register.filter
def clock(seconds: int | float | None) -> str:
    """A duration in seconds as M:SS, as the training clock shows it."""
    whole = max(0, round(float(seconds or 0)))
    return f"{whole // 60}:{whole % 60:02d}"


@register.filter
def gap(milliseconds: int | float | None) -> str:
    """The gap to first as +S.mmm (or +M:SS.mmm past a minute); first place shows a dash."""
    if not milliseconds:
        return "—"
    if milliseconds < 60_000:
        return f"+{milliseconds / 1000:.3f}"
    return f"+{laptime(milliseconds)}"
