"""What every router of the API shares: the error's shape and the statuses of refusals."""

from __future__ import annotations

from ninja import Schema


class Error(Schema):
    code: str
    message: str
    errors: dict[str, str] | None = None  # each input at fault, where a service said which


# The refusals an operation may answer with, for its documented responses.
REFUSED = {400: Error, 401: Error, 403: Error, 404: Error, 409: Error, 429: Error, 503: Error}
