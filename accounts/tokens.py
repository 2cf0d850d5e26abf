"""Personal access tokens for the API (/api/v1/; docs/api.md).

A token is ``plt_`` and 40 characters of ``secrets.token_urlsafe``: 240 random bits, so it is
looked up by the SHA-256 of the secret alone (a guess matches no digest; nothing to compare in
constant time). The secret is shown once, when it is made, and never stored. A token carries its
racer's rights cut to its scopes (``TokenScope``): ``admin`` only for league staff, and only
while they are staff. It stops working when it expires, is revoked, or its racer's account is
disabled; its last use is kept to the minute.
"""

from __future__ import annotations

import hashlib
import secrets
from datetime import timedelta

from django.contrib.auth.models import AbstractBaseUser
from django.db import IntegrityError, transaction
from django.utils import timezone

from accounts.models import AccessToken, TokenScope

PREFIX = "plt_"
SECRET_LENGTH = len(PREFIX) + 40
SHOWN_PREFIX = len(PREFIX) + 8  # what lists show of a secret
EXPIRY_DAYS = (7, 30, 90, 365)  # as GitHub's fine-grained tokens offer, with no "never"
LIVE_TOKENS_MAX = 20  # a racer's tokens in use at once
LAST_USE_EVERY = timedelta(minutes=1)  # a token's last use is written at most this often


class TokenRefused(Exception):
    """The token cannot be made: the message says why, in a racer's words."""


def digest_of(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


def token_create(
    *, owner: AbstractBaseUser, name: str, scopes: list[str], days: int
) -> tuple[AccessToken, str]:
    """A new token of ``owner``'s and its secret (shown to them once, stored nowhere)."""
    name = name.strip()
    if not name:
        raise TokenRefused("Give the token a name, to tell it from your others.")
    chosen = set(scopes)
    if not chosen or not chosen <= set(TokenScope.values):
        raise TokenRefused("Choose what the token may do: read, train, race or admin.")
    if TokenScope.ADMIN in chosen and not owner.is_staff:
        raise TokenRefused("Only league staff may make a token with the admin scope.")
    if days not in EXPIRY_DAYS:
        raise TokenRefused(f"A token lasts {', '.join(map(str, EXPIRY_DAYS))} days.")
    secret = PREFIX + secrets.token_urlsafe(30)
    with transaction.atomic():
        if tokens_live(owner=owner).count() >= LIVE_TOKENS_MAX:
            raise TokenRefused(
                f"You have {LIVE_TOKENS_MAX} tokens in use: revoke one you no longer need first."
            )
        try:
            with transaction.atomic():
                token = AccessToken.objects.create(
                    owner=owner,
                    name=name,
                    scopes=" ".join(sorted(chosen)),
                    prefix=secret[:SHOWN_PREFIX],
                    digest=digest_of(secret),
                    expires_at=timezone.now() + timedelta(days=days),
                )
        except IntegrityError:
            raise TokenRefused(f"You already have a token named {name!r}.") from None
    return token, secret


def token_revoke(*, owner: AbstractBaseUser, token_id: int) -> AccessToken | None:
    """Revoke ``owner``'s token ``token_id``: it stops working at once. None where ``owner``
    has no such token in use."""
    token = tokens_live(owner=owner).filter(pk=token_id).first()
    if token is None:
        return None
    token.revoked_at = timezone.now()
    token.save(update_fields=["revoked_at"])
    return token


def tokens_live(*, owner: AbstractBaseUser):
    """``owner``'s tokens not revoked (expired ones included: the list says so)."""
    return AccessToken.objects.filter(owner=owner, revoked_at__isnull=True)


def token_for(secret: str) -> AccessToken | None:
    """The token whose secret this is, where it still works (with its owner loaded); its last
    use noted. None for anything else: a malformed, unknown, expired or revoked secret, or a
    disabled account."""
    if len(secret) != SECRET_LENGTH or not secret.startswith(PREFIX):
        return None
    now = timezone.now()
    token = (
        AccessToken.objects.select_related("owner")
        .filter(digest=digest_of(secret), revoked_at__isnull=True, expires_at__gt=now)
        .first()
    )
    if token is None or not token.owner.is_active:
        return None
    if token.last_used_at is None or now - token.last_used_at >= LAST_USE_EVERY:
        AccessToken.objects.filter(pk=token.pk).update(last_used_at=now)
        token.last_used_at = now
    return token


def scopes_of(token: AccessToken) -> frozenset[str]:
    """What ``token`` may do now: its scopes, less admin once its racer is no longer staff."""
    scopes = token.scope_set
    return scopes if token.owner.is_staff else scopes - {TokenScope.ADMIN}
