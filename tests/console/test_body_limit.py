"""Request bodies over their limit are refused before Django reads them, in words, with 413."""

import json

import pytest
from django.urls import reverse

from tests import asgi

pytestmark = pytest.mark.django_db(transaction=True)


async def post(path: str, chunks: list[bytes], declared: int | None) -> tuple[int, bytes]:
    """(status, body) of a POST to the whole ASGI application, its body sent in ``chunks``."""
    headers = {"host": "127.0.0.1", "content-type": "application/octet-stream"}
    if declared is not None:
        headers["content-length"] = str(declared)
    response = await asgi.request("POST", path, headers, chunks)
    return response.status, response.body


@pytest.fixture
def limits(settings):
    settings.PITLANE_MAX_BODY = 1000
    settings.PITLANE_MAX_IMPORT_BODY = 5000


async def test_a_body_declared_over_the_limit_is_refused_at_once(limits):
    status, body = await post(reverse("login"), [b""], declared=2000)
    assert status == 413
    assert b"at most 1,000 bytes" in body
    assert b"Nothing was saved" in body


async def test_a_body_sent_in_chunks_is_refused_once_it_passes_the_limit(limits):
    status, body = await post(reverse("login"), [b"x" * 600, b"x" * 600, b"x" * 600], None)
    assert status == 413
    assert b"at most 1,000 bytes" in body


@pytest.mark.parametrize("name", ["archives:model-import", "api-v1:model-import"])
async def test_the_model_import_takes_its_own_larger_limit(limits, name):
    path = reverse(name)
    status, _ = await post(path, [b"x" * 2000], declared=2000)
    assert status != 413  # read by Django (which asks for a sign-in)
    status, body = await post(path, [b"x" * 6000], declared=6000)
    assert status == 413
    assert b"at most 5,000 bytes" in body


async def test_the_apis_refusal_is_json_in_its_shape(limits):
    status, body = await post(reverse("api-v1:models_list"), [b""], declared=2000)
    assert status == 413
    assert json.loads(body) == {
        "code": "too_large",
        "message": "The console takes at most 1,000 bytes in one request here: send something "
        "smaller.",
    }


async def test_a_body_under_the_limit_reaches_django(limits):
    status, _ = await post(reverse("login"), [b"x" * 500], declared=500)
    assert status in (200, 403)  # the sign-in form (CSRF refuses a bare POST), not a 413
