import re
from datetime import datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import pytest
from django.conf import settings
from django.test import Client
from django.urls import reverse

from tests.helpers.models import ready_model
from training.models import RLModel

pytestmark = pytest.mark.django_db


def nav_labels(response) -> list[str]:
    nav = re.search(r'<ul class="nav-links">(.*?)</ul>', response.text, re.S).group(1)
    return re.findall(r">([^<]+)</a>", nav)


def test_a_visitor_sees_the_public_sections_and_how_to_start(client):
    response = client.get(reverse("home"))
    assert nav_labels(response) == ["Races", "Leaderboards", "Help"]
    assert "Create your racer account" in response.text


def test_a_racer_sees_their_sections_and_next_steps(client, alice):
    client.force_login(alice)
    response = client.get(reverse("home"))
    assert nav_labels(response) == ["Models", "Garage", "Races", "Leaderboards", "Help"]
    assert "Your next steps" in response.text
    assert "Build a vehicle" in response.text


def test_staff_also_see_system_and_admin(client, stella):
    client.force_login(stella)
    assert nav_labels(client.get(reverse("home"))) == [
        "Models",
        "Garage",
        "Races",
        "Leaderboards",
        "Help",
        "System",
        "Admin",
    ]


def test_the_current_section_is_marked(client, alice):
    client.force_login(alice)
    response = client.get(reverse("training:garage"))
    assert '<a href="/garage/" aria-current="page">Garage</a>' in response.text


def test_the_system_page_is_for_staff_only(client, alice, stella):
    client.force_login(alice)
    assert client.get(reverse("system")).status_code == 302
    client.force_login(stella)
    response = client.get(reverse("system"))
    assert response.status_code == 200
    assert "Worker probe" in response.text


def test_an_unknown_page_gets_a_readable_404(client):
    response = client.get("/no-such-page/")
    assert response.status_code == 404
    assert "This page is not on the track" in response.text


@pytest.mark.urls("tests.console.broken_urls")
def test_a_server_error_gets_a_readable_500_without_a_traceback():
    client = Client(raise_request_exception=False)
    response = client.get("/broken/")
    assert response.status_code == 500
    assert "Something broke on our side" in response.text
    assert "Traceback" not in response.text
    assert "ZeroDivisionError" not in response.text


@pytest.mark.urls("tests.console.broken_urls")
def test_a_database_that_does_not_answer_gets_a_readable_503():
    client = Client(raise_request_exception=False)
    response = client.get("/database-down/")
    assert response.status_code == 503 and response["Retry-After"] == "30"
    assert "The console cannot reach its database" in response.text
    assert "10.0.0.5" not in response.text and "Traceback" not in response.text


def test_an_expired_form_gets_a_readable_403(alice):
    client = Client(enforce_csrf_checks=True)
    response = client.post(reverse("login"), {"username": "alice", "password": "x"})
    assert response.status_code == 403
    assert "That form has expired" in response.text


@pytest.mark.parametrize(
    ("cookie", "shown", "zone"),
    [
        ("Asia/Tokyo", "2 Mar 2026, 08:30", "Asia/Tokyo"),
        ("America/Vancouver", "1 Mar 2026, 15:30", "America/Vancouver"),
        ("Mars/Olympus_Mons", "1 Mar 2026, 23:30", "UTC"),  # not a zone: the server's
        ("../../etc/passwd", "1 Mar 2026, 23:30", "UTC"),
    ],
)
def test_dates_are_written_in_the_zone_the_browser_names(
    client, alice, tracks, cookie, shown, zone
):
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(
        created_at=datetime(2026, 3, 1, 23, 30, tzinfo=ZoneInfo("UTC"))
    )
    client.force_login(alice)
    client.cookies["pitlane_tz"] = cookie
    page = client.get(reverse("training:model-list")).text
    assert f'<time datetime="2026-03-01T23:30:00+00:00" data-when="datetime">{shown}</time>' in page
    assert f"times in <span data-time-zone>{zone}</span>" in page


def test_no_template_comment_spans_lines():
    """``{# #}`` ends at the line's end: one that goes on shows the racer its source."""
    roots = [Path(settings.BASE_DIR) / "templates", *Path(settings.BASE_DIR).glob("*/templates")]
    broken = [
        f"{path}:{number}"
        for root in roots
        for path in root.rglob("*.html")
        for number, line in enumerate(path.read_text().splitlines(), start=1)
        if "{#" in line and "#}" not in line.split("{#", 1)[1]
    ]
    assert broken == []
