"""Every operation of the API's document, tried as another racer and without a token: no
racer's id ever reaches another's row (404, as a missing one), nothing answers without a token
(401), and nothing answers 500. The paths are read from the OpenAPI document, so an operation
added later is tried too."""

from __future__ import annotations

import re

import pytest

from api.v1 import api
from racing import live_races
from racing.models import LiveEntry, Submission
from tests.helpers.accounts import api_token
from tests.helpers.league import event
from tests.helpers.models import ready_model
from training.models import EvaluationJob, RewardFunction

ALL_SCOPES = ["read", "train", "race"]
BODIES = {  # a well-formed body for each operation that takes one
    "/api/v1/models": {"files": {}},
    "/api/v1/models/{model_id}/clone": {"name": "copy"},
    "/api/v1/models/{model_id}/evaluations": {},
    "/api/v1/events/{slug}/submissions": {"model": 0},
    "/api/v1/reward-functions/validate": {"source": ""},
    "/api/v1/reward-functions": {"name": "mine", "source": ""},
    "/api/v1/reward-functions/{function_id}": {"name": "mine", "source": ""},
    "/api/v1/models/import/confirm": {"kept": "x"},
    "/api/v1/events/{slug}/live": {},
    "/api/v1/events/{slug}/live/queue": {"model": 0},
    "/api/v1/events/{slug}/winner": {},
}


def operations():
    for path, methods in api.get_openapi_schema()["paths"].items():
        for method in methods:
            yield method, path


@pytest.mark.slow  # every operation, twice
def test_no_operation_reaches_another_racers_rows_or_answers_without_a_token(
    alice, bob, tracks, client
):
    model = ready_model(alice)
    race = event("Time trial", laps_required=1)
    evaluation = EvaluationJob.objects.create(model=model, track=model.track)
    submission = Submission.objects.create(event=race, racer=alice, model=model, model_name="m")
    function = RewardFunction.objects.create(owner=alice, name="hers", source="x")
    session = live_races.live_session_open(event=race, facilitator=alice)
    entry = live_races.live_entry_join(session=session, racer=alice, model=model)
    ids = {
        "model_id": model.pk,
        "evaluation_id": evaluation.pk,
        "submission_id": submission.pk,
        "slug": race.slug,
        "kind": "physical",
        "function_id": function.pk,
        "entry_id": entry.pk,
        "action": "up",
        "name": "Test season",
    }
    hers = api_token(bob, *ALL_SCOPES)
    tried = 0
    for method, path in operations():
        url = re.sub(r"{(\w+)}", lambda m: str(ids[m.group(1)]), path)
        body = BODIES.get(path)
        kwargs = {"content_type": "application/json", "data": body} if body is not None else {}
        anonymous = getattr(client, method)(url, **kwargs)
        assert anonymous.status_code == 401, (method, path, anonymous.status_code)
        assert anonymous.json()["code"] == "unauthenticated"
        answer = getattr(client, method)(url, **kwargs, **hers)
        assert answer.status_code < 500, (method, path, answer.content[:200])
        if any(
            name in path
            for name in ("{model_id}", "{submission_id}", "{function_id}", "{entry_id}")
        ):
            assert answer.status_code == 404, (method, path, answer.status_code)
        tried += 1
    assert tried >= 20
    model.refresh_from_db()
    assert model.status == model.Status.READY  # nothing of alice's moved
    assert EvaluationJob.objects.filter(model=model).count() == 1
    assert RewardFunction.objects.get(pk=function.pk).source == "x"
    assert LiveEntry.objects.get(pk=entry.pk).status == LiveEntry.Status.WAITING
