"""``{% racer user %}``: a racer as leaderboards show them, by their profile."""

from __future__ import annotations

from django import template
from django.contrib.auth.models import AbstractBaseUser
from django.core.exceptions import ObjectDoesNotExist

from accounts.models import Profile

register = template.Library()


@register.inclusion_tag("accounts/includes/racer.html")
def racer(user: AbstractBaseUser) -> dict:
    """The racer's avatar, racer name and country; an account with no profile yet (made before
    profiles existed) shows its username in a plain avatar. Fetch ``racer__profile`` with the
    rows (``select_related``) so that a table of racers costs one query."""
    try:
        profile = user.profile
    except ObjectDoesNotExist:
        profile = Profile(user=user, racer_name=user.get_username(), avatar_colour="slate")
    return {"profile": profile}
