"""No slow step runs inside a write transaction: on SQLite a transaction holds the one write lock
from its start (IMMEDIATE), so a route check, a preview or a sandbox run inside one makes every
other writer wait (issue 42: a route file checked for 221 s in the admin's transaction)."""

import pytest
from django.db import transaction
from django.urls import reverse

from common import transactions
from common.transactions import SlowStepInTransaction
from tests import routes
from tests.helpers.tracks import upload
from training import rewards, services
from training.models import Track

pytestmark = pytest.mark.django_db


@pytest.fixture
def route_checks(monkeypatch) -> list[bool]:
    """Whether a transaction of the code's was open at each route check."""
    seen, load = [], services.simulator_tracks.load

    def watched(source):
        seen.append(transactions.in_transaction())
        return load(source)

    monkeypatch.setattr(services.simulator_tracks, "load", watched)
    return seen


def test_a_staff_upload_checks_its_route_file_outside_any_transaction(admin_client, route_checks):
    response = upload(admin_client, "counterclockwise", "club_oval")
    assert response.status_code == 302
    assert route_checks and not any(route_checks)  # the form's check and track_add's
    track = Track.objects.get(name="club_oval")
    route_checks.clear()
    change = reverse("admin:training_track_change", args=[track.pk])
    fields = {
        "display_name": "Club oval",
        "description": "",
        "difficulty": "beginner",
        "counterclockwise": "on",
    }
    assert admin_client.post(change, fields).status_code == 302
    assert route_checks == [False]
    assert not Track.objects.get(pk=track.pk).clockwise


def test_slow_steps_refuse_to_run_inside_a_transaction():
    route = routes.route_bytes("counterclockwise")
    with transaction.atomic():
        with pytest.raises(SlowStepInTransaction, match="route check"):
            services.track_check(name="inside", route=route, directions=["counterclockwise"])
        with pytest.raises(SlowStepInTransaction, match="validation in the sandbox"):
            rewards.reward_validate(
                source="def reward_function(params):\n    return 1.0\n", track="rookie-loop"
            )
    services.track_check(name="outside", route=route, directions=["counterclockwise"])
