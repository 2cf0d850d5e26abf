"""The API's OpenAPI document fuzzed with schemathesis against the running console (Daphne): for
every operation, requests generated from the document, valid and not, as a racer with every
racer's scope; no answer is a server error, and each one matches what the document declares
(its status, content type and body). A few examples an operation here, each run; the 2,000 and
more of `python -m bench.bench_api` are in docs/benchmarks.md."""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.specs.openapi.checks import positive_data_acceptance

from accounts.tokens import token_create
from api.v1 import api

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.slow]


schema = schemathesis.openapi.from_dict(api.get_openapi_schema())  # /api/v1/schema's document
# Every check of schemathesis's but that a request the document allows is accepted: the console
# refuses, in words, what no type can say (an empty reward function, a file that is no archive).
SEMANTIC = [positive_data_acceptance]


@pytest.fixture
def racers_token(alice) -> str:
    """A racer's token with every racer's scope: made once for each operation's examples."""
    return token_create(owner=alice, name="fuzz", scopes=["read", "train", "race"], days=7)[1]


@schema.parametrize()
# The same examples every run (derandomize): the suite checks what was found, the bench explores.
@settings(max_examples=4, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
def test_no_generated_request_gets_a_server_error_or_an_undeclared_answer(
    case, racers_token, tracks, daphne_server
):
    headers = {"Authorization": f"Bearer {racers_token}"}
    case.call_and_validate(base_url=daphne_server, headers=headers, excluded_checks=SEMANTIC)
