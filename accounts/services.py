"""Writes to racers' profiles."""

from __future__ import annotations

import re

from django.conf import settings
from django.contrib.auth.forms import PasswordResetForm
from django.contrib.auth.models import AbstractBaseUser
from django.db import IntegrityError, transaction

from accounts.email_changes import EmailChange, email_change_request
from accounts.models import RACER_NAME_MAX, RACER_NAME_MIN, AvatarColour, Profile


class RacerNameTaken(Exception):
    """Another racer took the name between the form's check and the save."""


def default_racer_name(*, username: str) -> str:
    """A racer name free for a new account: the username, its characters that a racer name
    may not hold made hyphens, padded to the shortest name, and numbered where it is taken."""
    base = re.sub(r"[^A-Za-z0-9_-]", "-", username)[:RACER_NAME_MAX].ljust(RACER_NAME_MIN, "-")
    name, number = base, 1
    while Profile.objects.filter(racer_name__iexact=name).exists():
        number += 1
        suffix = f"-{number}"
        name = base[: RACER_NAME_MAX - len(suffix)] + suffix
    return name


def profile_create(*, user: AbstractBaseUser) -> Profile:
    """The new account's profile: its username as its racer name where that is free, and
    one of the avatar colours, chosen by its id so that a leaderboard is not all one colour."""
    colours = AvatarColour.values
    for _ in range(5):  # another account may take the same name in between: try the next
        try:
            with transaction.atomic():
                return Profile.objects.create(
                    user=user,
                    racer_name=default_racer_name(username=user.get_username()),
                    avatar_colour=colours[(user.pk or 0) % len(colours)],
                )
        except IntegrityError:
            if Profile.objects.filter(user=user).exists():
                return Profile.objects.get(user=user)
    raise RacerNameTaken(user.get_username())


def profile_update(
    *, profile: Profile, racer_name: str, country: str, avatar_colour: str, email: str
) -> EmailChange:
    """Save what the racer chose on their profile page (already validated, the password checked
    where the email address changes), and the email address that password reset links and
    notifications go to: at once, or pending its confirmation (``accounts.email_changes``).
    Nothing is saved where another racer took the name (``RacerNameTaken``) or another account
    the address (``AddressTaken``) since the form's check."""
    profile.racer_name, profile.country, profile.avatar_colour = racer_name, country, avatar_colour
    try:
        with transaction.atomic():
            profile.save(update_fields=["racer_name", "country", "avatar_colour"])
            return email_change_request(profile=profile, email=email)
    except IntegrityError:
        raise RacerNameTaken(racer_name) from None


def profile_ensure(*, user: AbstractBaseUser) -> Profile:
    """The racer's profile; an account made before profiles existed (or loaded from a fixture,
    which sends no signal) gets its own on first sight."""
    profile = Profile.objects.filter(user=user).select_related("user").first()
    return profile or profile_create(user=user)


def password_reset_email_send(*, email: str) -> int:
    """Email a one-time link that sets a new password to each active account with ``email``
    (Django's reset form finds them); how many were sent. Run by a worker, never in the request
    that asked: the request does the same work whether an account matches or not, so its time
    tells nobody who has one."""
    form = PasswordResetForm({"email": email})
    if not form.is_valid():
        return 0
    site_url = settings.PITLANE_SITE_URL.rstrip("/")
    accounts = list(form.get_users(form.cleaned_data["email"]))
    form.save(
        domain_override=site_url.split("://")[-1],
        subject_template_name="registration/password_reset_subject.txt",
        email_template_name="registration/password_reset_email.txt",
        extra_email_context={
            "site_url": site_url,
            "link_hours": settings.PASSWORD_RESET_TIMEOUT // 3600,
        },
    )
    return len(accounts)
