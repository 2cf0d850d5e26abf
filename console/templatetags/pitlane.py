"""Template tags and filters used across the site."""

from datetime import datetime

from django import template
from django.utils.html import format_html

from common.formatting import clock, gap, laptime
from common.time_zones import local_text

register = template.Library()


@register.simple_tag
def when(moment: datetime | None, style: str = "datetime") -> str:
    """A moment in the racer's time zone (see common.time_zones), as a ``<time>`` element the
    browser can relabel: ``{% when job.created_at %}`` or ``{% when line.at "time" %}``."""
    if moment is None:
        return "—"
    return format_html(
        '<time datetime="{}" data-when="{}">{}</time>',
        moment.isoformat(),
        style,
        local_text(moment, style),
    )


register.filter(laptime)
register.filter(clock)
register.filter(gap)
