"""Dates as every page of the site writes them: "26 Nov 2026, 19:46", never Django's English
default "Nov. 26, 2026, 7:46 p.m.". A plain ``{{ moment }}``, ``|date``, ``|date:"DATETIME_FORMAT"``
and ``{% when %}`` (common.time_zones.FORMATS, and console/time_zone.js in the browser) agree."""

from common.time_zones import FORMATS

DATETIME_FORMAT = FORMATS["datetime"]
DATE_FORMAT = "j M Y"
TIME_FORMAT = "H:i"
SHORT_DATETIME_FORMAT = FORMATS["datetime"]
SHORT_DATE_FORMAT = DATE_FORMAT
MONTH_DAY_FORMAT = "j F"
YEAR_MONTH_FORMAT = "F Y"
FIRST_DAY_OF_WEEK = 1  # Monday
