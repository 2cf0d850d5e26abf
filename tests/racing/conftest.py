"""Fixtures of the league tests: a community race that alice organises."""

import secrets

import pytest
from django.urls import reverse

from racing.models import Event


def race_form(**fields) -> dict:
    """The community race form as the page posts it, with a one-time token of its own."""
    return {
        "form_token": secrets.token_urlsafe(32),
        "name": "Friday night",
        "track": "pitlane-oval",
        "direction": "counterclockwise",
        "race_type": "TIME_TRIAL",
        "opens_at": "2026-01-01T00:00",
        "closes_at": "2099-01-01T00:00",
        "ranking_method": "BEST_LAP",
        "laps_required": 1,
        "laps_to_drive": 3,
        "off_track_penalty_s": 1,
        "crash_penalty_s": 2,
        "submissions_per_racer": 5,
        **fields,
    }


@pytest.fixture
def community_race(client, alice, tracks) -> Event:
    client.force_login(alice)
    response = client.post(reverse("racing:community-race-create"), race_form())
    assert response.status_code == 302, response.context["form"].errors
    client.logout()
    return Event.objects.get(name="Friday night")
