"""What every router of the API shares: the error's shape and the statuses of refusals."""

from __future__ import annotations

import enum

from django.db import models
from ninja import Schema


class Error(Schema):
    code: str
    message: str
    errors: dict[str, str] | None = None  # each input at fault, where a service said which


# The refusals an operation may answer with, for its documented responses.
REFUSED = {400: Error, 401: Error, 403: Error, 404: Error, 409: Error, 429: Error, 503: Error}


def named_choices(choices: type[models.TextChoices], name: str) -> type[enum.Enum]:
    """``choices``' values as a string enum called ``name`` in the OpenAPI document: Django's
    choices of many models are all called ``Status``, and the document keeps one schema per
    name, so each is given its own (the fuzzed document once said a model's status was a
    training job's)."""
    return enum.Enum(name, {value: value for value in choices.values}, type=str)
