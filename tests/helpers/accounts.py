"""The suite's racers: each has the same password."""

import itertools

from django.contrib.auth.models import User

PASSWORD = "correct-horse-battery-staple"


def racer(username: str, **extra) -> User:
    """A racer who logs in with ``PASSWORD``; ``extra``: the user's other fields."""
    return User.objects.create_user(username=username, password=PASSWORD, **extra)


_TOKEN_NAMES = itertools.count()


def api_token(owner: User, *scopes: str) -> dict[str, str]:
    """The header of a new API token of ``owner``'s with ``scopes``, for the test client."""
    from accounts.tokens import token_create

    name = f"test token {next(_TOKEN_NAMES)}"
    secret = token_create(owner=owner, name=name, scopes=list(scopes), days=7)[1]
    return {"HTTP_AUTHORIZATION": f"Bearer {secret}"}
