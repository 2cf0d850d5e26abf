"""Pages say a race's or an evaluation's state in one place, its status, never a stale message
beside it."""

import pytest
from django.urls import reverse

from racing import services
from racing.models import Submission
from tests.helpers.evaluations import EVALUATION_FORM
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def test_a_racing_submission_says_its_status_and_nothing_that_contradicts_it(client, alice):
    trial = event()
    racing = Submission.objects.create(
        event=trial, racer=alice, model_name="m", status=Submission.Status.IN_PROGRESS
    )
    client.force_login(alice)
    page = client.get(racing.get_absolute_url()).text
    assert 'data-submission-status="IN_PROGRESS">In progress</span>' in page
    assert "soon" not in page.lower()
    assert "queued" not in page.lower()

    rows = client.get(reverse("racing:submission-list")).text
    assert "In progress" in rows and "soon" not in rows.lower()


def test_a_disqualified_run_says_the_word_once(client, alice):
    submission = scored(event(), alice, 9_000, 9_000, 9_000)
    services.submission_disqualify(
        submission=submission, reason="Disqualified by the league staff."
    )
    client.force_login(alice)
    page = client.get(submission.get_absolute_url()).text
    assert "Disqualified by the league staff." in page
    assert "Disqualified: Disqualified" not in page


def test_a_reason_the_staff_typed_follows_the_word(alice):
    submission = scored(event(), alice, 9_000, 9_000, 9_000)
    services.submission_disqualify(submission=submission, reason="Cut the chicane on lap 2.")
    assert submission.disqualification_text == "Disqualified: Cut the chicane on lap 2."
    submission.disqualification_reason = ""
    assert submission.disqualification_text == "Disqualified"


def test_a_new_evaluation_page_carries_no_queued_message_beside_its_live_status(client, alice):
    model = ready_model(alice)
    client.force_login(alice)
    response = client.post(
        reverse("training:evaluation-create", args=[model.pk]),
        EVALUATION_FORM,
        follow=True,
    )
    assert "The evaluation is queued." not in response.text
    assert "data-live-status>Queued" in response.text
