"""Changing a racer's email address, the one that password reset links and notifications go to.

The profile form asks for the password before the address changes (a session thief must not
redirect the reset link). An address belongs to one account, whatever its capitals: the profile
form says so, and the writes below check again under a lock (``_address_lock``), since the
address lives on Django's own user table, where this app adds no constraint.

Where the console sends email, a new address is only pending (on the racer's ``Profile``) until
its racer follows the link sent to it: a single-use token, stored as its SHA-256 and compared in
constant time, that works for ``EMAIL_LINK_DAYS`` days and only for the account that asked. The
old address is told of the change. Where the console sends no email (no ``PITLANE_EMAIL_URL``)
there is no mail to misdirect and no way to verify: the address is saved at once, unverified,
and nothing is sent. Removing the address needs the password too, and no link.
"""

from __future__ import annotations

import enum
import hashlib
import logging
import secrets
from datetime import timedelta

from django.conf import settings
from django.contrib.auth import get_user_model
from django.contrib.auth.models import AbstractBaseUser
from django.core.mail import send_mail
from django.db import connection, transaction
from django.template.loader import render_to_string
from django.urls import reverse
from django.utils import timezone
from django.utils.crypto import constant_time_compare

from accounts.models import Profile

logger = logging.getLogger(__name__)

EMAIL_LINK_DAYS = 3  # [days] a confirmation link works this long, and once

ADDRESS_TAKEN = "That address belongs to another account."
LINK_USED = (
    "This link no longer works: it was used already, a newer one replaced it, or it was sent "
    "for another account (check whom you are logged in as). Your email address is unchanged."
)
LINK_EXPIRED = (
    f"This link has expired: a confirmation link works for {EMAIL_LINK_DAYS} days. Your email "
    "address is unchanged; enter the new one on your profile again for a fresh link."
)
LINK_ADDRESS_TAKEN = (
    "That address now belongs to another account, so it cannot be yours as well. Your email "
    "address is unchanged."
)


class EmailChange(enum.Enum):
    """What saving the profile did to the email address."""

    UNCHANGED = "unchanged"
    SAVED = "saved"  # removed, or saved at once where the console sends no email
    PENDING = "pending"  # waits for its confirmation link to be followed


class AddressTaken(Exception):
    """Another account has the address (it may have taken it after the form's check)."""


class LinkRefused(Exception):
    """A confirmation link that changes nothing; its message says why, in the racer's words."""


def console_sends_email() -> bool:
    """Whether this console sends any email (its operator set ``PITLANE_EMAIL_URL``)."""
    return settings.PITLANE_PASSWORD_RESET_BY_EMAIL or settings.PITLANE_EMAIL_NOTIFICATIONS


def address_taken(*, email: str, user: AbstractBaseUser) -> bool:
    """Whether an account other than ``user`` has ``email``, ignoring capitals."""
    others = get_user_model().objects.exclude(pk=user.pk)
    return bool(email) and others.filter(email__iexact=email).exists()


def email_change_request(*, profile: Profile, email: str) -> EmailChange:
    """Change ``profile``'s racer's address to ``email`` (already validated, the password
    checked): at once where it is removed or the console sends no email, else pending until
    the link sent to it is followed. Raises ``AddressTaken``."""
    user = profile.user
    if email == user.email:  # the current address typed again: any pending change is cancelled
        if profile.pending_email or profile.pending_email_token:
            _pending_set(profile, email="", token="")
        return EmailChange.UNCHANGED
    old_address, sends = user.email, console_sends_email()
    with transaction.atomic():
        _address_lock(email)
        if address_taken(email=email, user=user):
            raise AddressTaken(email)
        if email and sends:
            token = secrets.token_urlsafe(32)
            _pending_set(profile, email=email, token=token)
            transaction.on_commit(lambda: _send_link(profile, token=token))
            outcome = EmailChange.PENDING
        else:
            user.email = email
            user.save(update_fields=["email"])
            _pending_set(profile, email="", token="")
            outcome = EmailChange.SAVED
        if old_address and sends:
            transaction.on_commit(lambda: _tell_old_address(profile, old_address, outcome))
    return outcome


def pending_email_for_link(*, user: AbstractBaseUser, token: str) -> str:
    """The address that ``token``'s link would make ``user``'s; raises ``LinkRefused``."""
    profile = Profile.objects.filter(user=user).first()
    refusal = _link_refusal(profile, token)
    if refusal:
        raise LinkRefused(refusal)
    return profile.pending_email


def email_change_confirm(*, user: AbstractBaseUser, token: str) -> str:
    """Make the pending address that ``token`` was sent to ``user``'s own; the new address.
    A link works once: refused (``LinkRefused``) when used, replaced, expired, another
    account's, or when another account has taken the address since."""
    with transaction.atomic():
        profile = Profile.objects.select_for_update().select_related("user").filter(user=user)
        profile = profile.first()
        if profile is None:
            raise LinkRefused(LINK_USED)
        refusal = _link_refusal(profile, token)
        if refusal is None:
            _address_lock(profile.pending_email)
            if address_taken(email=profile.pending_email, user=user):
                refusal = LINK_ADDRESS_TAKEN
        new_address = profile.pending_email
        if refusal != LINK_USED:  # a used link leaves a newer pending address alone
            if refusal is None:
                profile.user.email = new_address
                profile.user.save(update_fields=["email"])
            _pending_set(profile, email="", token="")
    if refusal:
        raise LinkRefused(refusal)
    return new_address


def _link_refusal(profile: Profile | None, token: str) -> str | None:
    if profile is None or not profile.pending_email or not profile.pending_email_token:
        return LINK_USED
    if not constant_time_compare(profile.pending_email_token, _digest(token)):
        return LINK_USED
    sent_at = profile.pending_email_sent_at
    if sent_at is None or timezone.now() - sent_at > timedelta(days=EMAIL_LINK_DAYS):
        return LINK_EXPIRED
    return None


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def _pending_set(profile: Profile, *, email: str, token: str) -> None:
    profile.pending_email = email
    profile.pending_email_token = _digest(token) if token else ""
    profile.pending_email_sent_at = timezone.now() if token else None
    profile.save(update_fields=["pending_email", "pending_email_token", "pending_email_sent_at"])


def _address_lock(email: str) -> None:
    """Hold, until the transaction ends, the right to give ``email`` to an account, so that
    two accounts cannot both check it is free and both take it. SQLite's IMMEDIATE
    transactions (console/settings/base.py) already hold the whole database's write lock;
    PostgreSQL takes an advisory lock on the address."""
    if email and connection.vendor == "postgresql":
        with connection.cursor() as cursor:
            cursor.execute("SELECT pg_advisory_xact_lock(hashtext(%s))", [email.lower()])


def _send_link(profile: Profile, *, token: str) -> None:
    site_url = settings.PITLANE_SITE_URL.rstrip("/")
    link = site_url + reverse("accounts:email-confirm", kwargs={"token": token})
    _mail(
        "Pitlane: confirm your new email address",
        "accounts/email_change_link.txt",
        {"profile": profile, "link": link, "days": EMAIL_LINK_DAYS},
        profile.pending_email,
    )


def _tell_old_address(profile: Profile, old_address: str, outcome: EmailChange) -> None:
    site_url = settings.PITLANE_SITE_URL.rstrip("/")
    context = {
        "profile": profile,
        "removed": outcome is EmailChange.SAVED,
        "days": EMAIL_LINK_DAYS,
        "password_url": site_url + reverse("password_change"),
    }
    _mail(
        "Pitlane: your email address is being changed",
        "accounts/email_change_notice.txt",
        context,
        old_address,
    )


def _mail(subject: str, template: str, context: dict, to: str) -> None:
    try:
        send_mail(subject, render_to_string(template, context), None, [to])
    except Exception:  # the change stands; a mail server's trouble is logged, not the racer's
        logger.exception("Could not send %s for profile %s", template, context["profile"].pk)
