"""Who calls the API: a personal access token (``Authorization: Bearer plt_…``,
accounts.tokens), or the console's own session (its pages' fetches, CSRF checked on writes).

A token acts as its racer within its scopes (``need``); a session has every scope its racer
has. Each token's requests are counted (``PITLANE_RATE_API``, common.ratelimits) and refused past
the rate with 429 and ``Retry-After``, as the pages' limits are.
"""

from __future__ import annotations

from django.http import HttpRequest
from ninja.errors import AuthenticationError
from ninja.security import HttpBearer, SessionAuth

from accounts import tokens
from accounts.models import TokenScope
from api.errors import ApiError, counted

# What each scope lets a token do, for the refusal's words.
DOES = {
    TokenScope.READ: "read",
    TokenScope.TRAIN: "train, change or delete models",
    TokenScope.RACE: "race",
    TokenScope.ADMIN: "act as league staff",
}


class TokenAuth(HttpBearer):
    def authenticate(self, request: HttpRequest, token: str):
        """The token's racer; a request that sends a token that does not work is refused (401)
        then and there, never taken for the session its browser may also hold."""
        found = tokens.token_for(token)
        if found is None:
            raise AuthenticationError()
        counted(request, "api", key=f"token:{found.pk}", every_method=True)
        request.access_token = found
        request.user = found.owner
        return found.owner


def scopes(request: HttpRequest) -> frozenset[str]:
    """What this request may do: its token's scopes, or a session's racer's every right."""
    token = getattr(request, "access_token", None)
    if token is not None:
        return tokens.scopes_of(token)
    everything = frozenset(TokenScope.values)
    return everything if request.user.is_staff else everything - {TokenScope.ADMIN}


def need(request: HttpRequest, scope: str) -> None:
    """Refuse (403) a request whose token lacks ``scope``."""
    if scope not in scopes(request):
        raise ApiError(
            403,
            "scope",
            f"This token may not {DOES[scope]}: make one with the {scope} scope on your "
            "profile page.",
        )


AUTH = [TokenAuth(), SessionAuth()]
