"""The site speaks in one voice: its own words for a form's mistakes (never Django's "This field
is required."), one way of writing a date, and tracks and directions as racers know them."""

from __future__ import annotations

import inspect
from datetime import UTC, datetime

import pytest
from django import forms
from django.core.files.uploadedfile import SimpleUploadedFile
from django.template import engines
from django.utils import timezone

from analysis.models import Rescoring
from common.forms import RacerWords
from simulator.trace import to_csv
from tests.helpers.analysis import HAND_WRITTEN
from tests.helpers.league import event
from tests.helpers.models import ready_model
from training import artifacts, configuration

pytestmark = pytest.mark.django_db

DJANGOS_WORDS = [
    "This field is required.",
    "Ensure this value",
    "Select a valid choice",
    "Enter a whole number",
    "Enter a number.",
    "Enter a valid",
]
LONG = "x" * 300


def test_every_form_of_the_site_takes_the_sites_words():
    from accounts import forms as accounts_forms
    from analysis import forms as analysis_forms
    from console import forms as console_forms
    from racing import forms as racing_forms
    from training import forms as training_forms

    modules = [accounts_forms, analysis_forms, console_forms, racing_forms, training_forms]
    found = [
        klass
        for module in modules
        for _, klass in inspect.getmembers(module, inspect.isclass)
        if issubclass(klass, forms.BaseForm) and klass.__module__ == module.__name__
    ]
    assert len(found) >= 10
    assert [k.__name__ for k in found if not issubclass(k, RacerWords)] == []


def test_a_form_names_the_field_and_its_limit_in_the_sites_words():
    class Example(RacerWords, forms.Form):
        name = forms.CharField(max_length=64)
        minutes = forms.IntegerField(label="Maximum training time [min]", min_value=10)
        speed = forms.FloatField(max_value=4)
        kept = forms.CharField(error_messages={"required": "Give your vehicle a name."})

    form = Example({"name": "n" * 70, "minutes": "5", "speed": "fast"})
    assert form.errors == {
        "name": ["Name is at most 64 characters long; this one has 70."],
        "minutes": ["Maximum training time [min] is at least 10."],
        "speed": ["Speed is a number, such as 2.5."],
        "kept": ["Give your vehicle a name."],  # a form's own message stays
    }


def test_a_file_name_too_long_is_said_with_the_limit_django_gives():
    class Example(RacerWords, forms.Form):
        archive = forms.FileField(max_length=5)

    form = Example({}, {"archive": SimpleUploadedFile("far-too-long.tar.gz", b"data")})
    assert form.errors == {
        "archive": ["Archive: its name is at most 5 characters; this one has 19."]
    }


def _said(response) -> str:
    return response.content.decode()


def test_no_racer_facing_form_answers_in_djangos_default_words(client, alice, tracks):
    model = ready_model(alice)
    event("Time trial")
    client.force_login(alice)
    answers = {
        "garage, empty": client.post("/garage/", {}),
        "garage, too long": client.post("/garage/", {"name": LONG, "shell_colour": "nope"}),
        "model, empty": client.post("/models/create/", {}),
        "model, too long": client.post(
            "/models/create/", {"name": LONG, "description": LONG, "track": "nowhere"}
        ),
        "evaluation": client.post(
            f"/models/{model.pk}/evaluate/", {"trials": "many", "off_track_penalty": "x"}
        ),
        "import, empty": client.post("/models/import/", {}),
        "reward function, empty": client.post("/models/reward-function/", {"name": LONG}),
        "validation, empty": client.post("/models/reward-function/validate/", {}),
        "submission, empty": client.post("/races/submit/", {}),
        "submission, wrong": client.post("/races/submit/", {"event": "999", "model": "x"}),
        "community race, empty": client.post("/races/community/new/", {}),
        "community race, too long": client.post(
            "/races/community/new/", {"name": LONG, "opens_at": "soon", "laps": "x"}
        ),
        "re-scoring, empty": client.post(f"/models/{model.pk}/analysis/rescore/", {}),
        "re-scoring, wrong": client.post(
            f"/models/{model.pk}/analysis/rescore/", {"reward_function": "x", "first": "-1"}
        ),
        "profile": client.post("/accounts/profile/", {"racer_name": LONG, "avatar_colour": "teal"}),
        "password change, empty": client.post("/accounts/password/", {}),
    }
    client.logout()
    answers["sign-up, empty"] = client.post("/accounts/signup/", {"username": ""})
    answers["sign-up, too long"] = client.post("/accounts/signup/", {"username": LONG})
    answers["sign-in, empty"] = client.post("/accounts/login/", {"username": ""})
    for what, response in answers.items():
        assert response.status_code < 500, what
        said = _said(response)
        assert [words for words in DJANGOS_WORDS if words in said] == [], what
    assert "Login name is needed." in _said(answers["sign-up, empty"])
    assert "Login name is at most 150 characters long; this one has 300." in _said(
        answers["sign-up, too long"]
    )
    assert "Login name is needed." in _said(answers["sign-in, empty"])
    assert (
        "A racer name is 2 to 64 letters, digits, hyphens (-) and underscores (_), no spaces; "
        "that one has 300." in _said(answers["profile"])
    )
    assert "Password is needed." in _said(answers["sign-in, empty"])


MOMENT = datetime(2026, 11, 26, 19, 46, tzinfo=UTC)


def test_a_moment_is_written_one_way_whatever_writes_it():
    template = engines["django"].from_string(
        '{% load pitlane %}{{ m }}|{{ m|date }}|{{ m|date:"DATETIME_FORMAT" }}|'
        '{{ m|date:"SHORT_DATETIME_FORMAT" }}|{% when m %}'
    )
    with timezone.override("UTC"):
        written = template.render({"m": MOMENT}).split("|")
    assert written[:4] == [
        "26 Nov 2026, 19:46",
        "26 Nov 2026",
        "26 Nov 2026, 19:46",
        "26 Nov 2026, 19:46",
    ]
    assert written[4].endswith(">26 Nov 2026, 19:46</time>")


def test_the_analysis_tab_writes_its_dates_and_directions_as_every_page_does(client, alice, tracks):
    model = ready_model(alice)
    artifacts.save(model, artifacts.training_trace(1), to_csv(HAND_WRITTEN))
    rescoring = Rescoring.objects.create(
        owner=alice, job=model.jobs.get(), reward_function="def reward_function(p): return 1.0"
    )
    Rescoring.objects.filter(pk=rescoring.pk).update(created_at=MOMENT)
    client.force_login(alice)
    said = _said(client.get(f"/models/{model.pk}/analysis/"))
    assert ">26 Nov 2026, 19:46</time>" in said
    assert "Nov. 26" not in said and "p.m." not in said
    assert "(counter-clockwise)" in said and "(counterclockwise)" not in said


def test_a_direction_reads_as_on_every_page():
    assert configuration.direction_words("counterclockwise") == "counter-clockwise"
    assert configuration.direction_words("clockwise") == "clockwise"
