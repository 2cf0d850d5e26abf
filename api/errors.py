"""The API's errors: JSON with a machine code and the words a page would show.

``{"code": "not_found", "message": "No model of yours has the id 7."}``, with the status that
fits (docs/api.md): 400 for input the console cannot take, 401 without a working token or
session, 403 for what the token's scopes or the racer's rights do not allow, 404 for what is not
there or not theirs (never 403: another racer's ids are not confirmed), 409 for what the
resource's state refuses, 413, 429 with ``Retry-After``. Never a traceback.
"""

from __future__ import annotations

import logging
import math

from django.core.exceptions import RequestDataTooBig
from django.http import Http404, HttpRequest, HttpResponse
from django.http.multipartparser import MultiPartParserError
from ninja import NinjaAPI
from ninja.errors import AuthenticationError, HttpError, ValidationError

from common import ratelimits
from common.refusals import Refused
from training import checkers, rewards

logger = logging.getLogger(__name__)


class ApiError(Exception):
    """A refusal: its status, machine code, words, each input at fault (``errors``, where
    there are some) and headers (Retry-After)."""

    def __init__(
        self,
        status: int,
        code: str,
        message: str,
        headers: dict[str, str] | None = None,
        errors: dict[str, str] | None = None,
    ) -> None:
        super().__init__(message)
        self.status, self.code, self.message = status, code, message
        self.headers = headers or {}
        self.errors = errors


def counted(request: HttpRequest, action: str, **how) -> None:
    """Count the request against the console's limit ``action`` (``common.ratelimits.over``,
    as the pages count theirs); refuse it (429, or 503 where the count failed closed) with
    ``Retry-After`` past the rate."""
    limited = ratelimits.over(request, action, **how)
    if limited is not None:
        raise rate_refusal(limited)


def rate_refusal(limited: ratelimits.Limited) -> ApiError:
    """A limit's refusal: 429 (503 where the count failed closed) with ``Retry-After``."""
    wait = str(max(1, math.ceil(limited.wait)))
    return ApiError(limited.status, "rate_limited", str(limited), {"Retry-After": wait})


def check_failed(error: Exception) -> ApiError:
    """A reward check that could not run (``training.checkers.FAILURES``): 503, the racer's
    input not at fault, and when every checker was busy, when to try again (as the pages'
    ``checkers.failure_response``)."""
    busy = isinstance(error, checkers.Busy)
    headers = {"Retry-After": str(checkers.RETRY_AFTER)} if busy else {}
    return ApiError(503, "unavailable", checkers.failure_words(error), headers)


async def reward_checked(
    source: str, track: str, *, racer: int, direction: str = "counterclockwise"
) -> rewards.Validation:
    """``training.checkers.reward_checked``: its validation, or a check that could not run
    raised as ``check_failed``'s 503."""
    checked = await checkers.reward_checked(source, track, racer=racer, direction=direction)
    if isinstance(checked, Exception):
        raise check_failed(checked)
    return checked


def answer(api: NinjaAPI, request: HttpRequest, error: ApiError) -> HttpResponse:
    body = {"code": error.code, "message": error.message}
    if error.errors:
        body["errors"] = error.errors
    response = api.create_response(request, body, status=error.status)
    for name, value in error.headers.items():
        response[name] = value
    return response


def _invalid_words(errors: list[dict]) -> str:
    """The first of pydantic's errors as a sentence: where, and what is wrong."""
    first = errors[0]
    where = ".".join(str(part) for part in first.get("loc", ()) if part not in ("body", "query"))
    return f"{where}: {first.get('msg', 'not valid')}." if where else f"{first.get('msg')}."


def install(api: NinjaAPI) -> None:
    """Every error the API answers takes the one shape."""

    @api.exception_handler(ApiError)
    def refused(request, error: ApiError):
        return answer(api, request, error)

    @api.exception_handler(Refused)
    def refused_by_a_service(request, refusal: Refused):
        """A service's refusal (``common.refusals``): its words, and each input at fault."""
        response = api.create_response(
            request,
            {"code": "invalid", "message": str(refusal), "errors": refusal.errors},
            status=400,
        )
        return response

    @api.exception_handler(ValidationError)
    def invalid(request, error: ValidationError):
        return answer(api, request, ApiError(400, "invalid", _invalid_words(error.errors)))

    @api.exception_handler(AuthenticationError)
    def unauthenticated(request, error):
        return answer(
            api,
            request,
            ApiError(
                401,
                "unauthenticated",
                "Send a working token as 'Authorization: Bearer plt_…' (make one on your "
                "profile page), or sign in to the console.",
            ),
        )

    @api.exception_handler(Http404)
    def not_found(request, error):
        return answer(api, request, ApiError(404, "not_found", str(error) or "Not found."))

    @api.exception_handler(HttpError)
    def http_error(request, error: HttpError):
        return answer(api, request, ApiError(error.status_code, "refused", str(error)))

    @api.exception_handler(MultiPartParserError)
    def unreadable_form(request, error):
        return answer(
            api,
            request,
            ApiError(400, "invalid", f"The request's multipart body cannot be read: {error}."),
        )

    @api.exception_handler(RequestDataTooBig)
    def too_big(request, error):
        return answer(api, request, ApiError(413, "too_large", "The request's body is too large."))

    @api.exception_handler(Exception)
    def internal(request, error):
        logger.exception("API request %s %s failed", request.method, request.path)
        return answer(
            api,
            request,
            ApiError(
                500, "internal", "The console failed to answer this: try again, or tell staff."
            ),
        )
