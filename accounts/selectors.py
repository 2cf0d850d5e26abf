"""Reads of racers' profiles: how a racer is named to other racers."""

from __future__ import annotations

from django.contrib.auth.models import AbstractBaseUser
from django.core.exceptions import ObjectDoesNotExist

from accounts.models import AvatarColour, Profile


def racer_profile(*, racer: AbstractBaseUser) -> Profile:
    """The racer's profile as others see it. An account without one (every account gets one
    as it is made, so only rows loaded behind the signal's back) is shown as "Racer #<id>",
    never by its login name, which is a credential; nothing is saved."""
    try:
        return racer.profile
    except ObjectDoesNotExist:
        return Profile(
            user=racer, racer_name=f"Racer #{racer.pk}", avatar_colour=AvatarColour.SLATE
        )


def racer_name(*, racer: AbstractBaseUser) -> str:
    """The name other racers know ``racer`` by, for plain text (messages, notifications)."""
    return racer_profile(racer=racer).racer_name
