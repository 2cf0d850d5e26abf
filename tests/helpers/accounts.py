"""The suite's racers: each has the same password."""

from django.contrib.auth.models import User

PASSWORD = "correct-horse-battery-staple"


def racer(username: str, **extra) -> User:
    """A racer who logs in with ``PASSWORD``; ``extra``: the user's other fields."""
    return User.objects.create_user(username=username, password=PASSWORD, **extra)
