"""``{% racer user %}``: a racer as leaderboards show them, by their profile."""

from __future__ import annotations

from django import template
from django.contrib.auth.models import AbstractBaseUser

from accounts.selectors import racer_name as named
from accounts.selectors import racer_profile

register = template.Library()


@register.inclusion_tag("accounts/includes/racer.html")
def racer(user: AbstractBaseUser) -> dict:
    """The racer's avatar, racer name and country; an account with no profile is "Racer #<id>"
    in a plain avatar, never its login name. Fetch ``racer__profile`` with the rows
    (``select_related``) so that a table of racers costs one query."""
    return {"profile": racer_profile(racer=user)}


@register.filter
def racer_name(user: AbstractBaseUser) -> str:
    """``{{ user|racer_name }}``: the racer name alone, where markup cannot go (an attribute)."""
    return named(racer=user)
