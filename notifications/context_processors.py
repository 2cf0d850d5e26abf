from django.http import HttpRequest
from django.utils.functional import SimpleLazyObject

from notifications import selectors


def bell(request: HttpRequest) -> dict:
    """The unread count for the bell in the navigation; counted only when a page shows it."""
    user = getattr(request, "user", None)
    if user is None or not user.is_authenticated:
        return {}
    return {
        "unread_notifications": SimpleLazyObject(lambda: selectors.unread_count(recipient=user))
    }
