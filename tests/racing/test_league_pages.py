from datetime import date, timedelta
from zoneinfo import ZoneInfo

import pytest
from django.core.files.storage import default_storage
from django.core.management import call_command
from django.db import connection
from django.test.utils import CaptureQueriesContext
from django.urls import reverse
from django.utils import timezone

from common.formatting import gap, laptime
from racing.forms import SubmissionForm
from racing.models import Event, Season
from racing.services import demo_season_load
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from training import artifacts
from training.models import RLModel
from training.selectors import UNTRAINED

pytestmark = pytest.mark.django_db


def test_the_demo_season_has_an_open_event_per_division_and_one_upcoming(tracks):
    season = demo_season_load(today=date(2026, 11, 21))
    events = {event.slug: event for event in season.events.all()}
    assert set(events) == {
        "open-time-trial-2026-11",
        "pro-object-avoidance-2026-11",
        "open-time-trial-2026-12",
    }
    november = events["open-time-trial-2026-11"]
    assert (november.division, november.race_type) == ("OPEN", "TIME_TRIAL")
    assert events["pro-object-avoidance-2026-11"].division == "PRO"
    assert november.closes_at == events["open-time-trial-2026-12"].opens_at


def test_loading_the_demo_season_twice_changes_nothing(tracks):
    call_command("loaddemoseason")
    call_command("loaddemoseason")
    assert Season.objects.count() == 1
    assert Event.objects.count() == 3


def test_the_demo_season_asks_for_the_tracks_first():
    with pytest.raises(Exception, match=r"run: manage\.py loadtracks"):
        call_command("loaddemoseason")


def test_the_races_page_lists_the_seasons_events_with_their_state(client, tracks):
    demo_season_load()
    response = client.get(reverse("racing:race-list"))
    assert response.status_code == 200
    assert response.text.count('<span class="badge badge-open">Open</span>') == 2
    assert response.text.count('<span class="badge badge-upcoming">Upcoming</span>') == 1


@pytest.fixture
def ranked_event(tracks, alice, bob):
    event = demo_season_load().events.get(division="OPEN", opens_at__lte=timezone.now())
    now = timezone.now()
    scored(event, alice, 31_002, 31_002, 31_002, model_name="a1", at=now)
    scored(event, bob, 29_450, 29_450, 29_450, model_name="b1", at=now - timedelta(hours=1))
    return event


def test_a_leaderboard_ranks_by_time_with_the_gap_to_first(client, ranked_event):
    response = client.get(ranked_event.get_absolute_url())
    rows = response.context["rankings"]
    assert [(r.position, r.racer.username, r.gap_ms) for r in rows] == [
        (1, "bob", 0),
        (2, "alice", 1552),
    ]
    assert "0:29.450" in response.text
    assert "+1.552" in response.text


def test_a_racer_sees_their_own_row_highlighted(client, alice, ranked_event):
    client.force_login(alice)
    response = client.get(ranked_event.get_absolute_url())
    assert '<tr class="mine">' in response.text
    assert response.text.index('class="mine"') > response.text.index("bob")


def test_the_leaderboards_page_shows_each_events_best_time(client, ranked_event):
    response = client.get(reverse("racing:leaderboard-list"))
    assert "0:29.450" in response.text


def test_an_unknown_event_is_a_404(client):
    assert client.get(reverse("racing:leaderboard", args=["nope"])).status_code == 404


@pytest.mark.parametrize(
    ("ms", "shown"), [(0, "0:00.000"), (29_450, "0:29.450"), (61_005, "1:01.005"), (None, "—")]
)
def test_times_show_as_minutes_seconds_and_milliseconds(ms, shown):
    assert laptime(ms) == shown


def test_gaps_show_as_seconds_and_first_place_as_a_dash():
    assert (gap(0), gap(1552), gap(75_000)) == ("—", "+1.552", "+1:15.000")


def test_the_submit_form_names_when_events_close_in_the_racers_time_zone(alice, tracks):
    trial = event("Late trial")
    label = SubmissionForm(racer=alice).fields["event"].label_from_instance
    with timezone.override(ZoneInfo("Asia/Tokyo")):
        tokyo = timezone.localtime(trial.closes_at)
        assert label(trial).endswith(f"closes {tokyo:%-d %b %Y, %H:%M})")


def test_a_visitor_is_offered_to_sign_up_and_never_to_manage_a_race(client, ranked_event):
    page = client.get(ranked_event.get_absolute_url())
    assert "Manage this race" not in page.text
    signup = f'href="{reverse("signup")}?next={ranked_event.get_absolute_url()}"'
    assert signup in page.text and "Sign up to race" in page.text
    assert "Sign up to race" in client.get(reverse("racing:race-list")).text


def test_only_the_organiser_of_a_community_race_is_offered_to_manage_it(
    client, community_race, alice, bob
):
    community_race.participants.add(bob)
    manage = reverse("racing:community-race-manage", args=[community_race.slug])
    client.force_login(bob)
    page = client.get(community_race.get_absolute_url())
    assert manage not in page.text and "Sign up to race" not in page.text
    client.force_login(alice)
    assert manage in client.get(community_race.get_absolute_url()).text


def test_watch_opens_the_runs_page_for_everyone_once_it_is_on_the_leaderboard(
    client, ranked_event, alice, bob
):
    fastest = ranked_event.rankings.get(racer=bob).submission
    board = client.get(ranked_event.get_absolute_url())
    assert f'href="{fastest.get_absolute_url()}#video"' in board.text

    page = client.get(fastest.get_absolute_url())  # a visitor, not logged in
    assert page.status_code == 200
    assert '<span class="racer-name">bob</span>' in page.text and "b1 in " in page.text
    assert "place on the leaderboard: <strong data-place>1</strong>" in page.text
    assert "your place" not in page.text
    assert "data-score>0:29.450</strong>" in page.text and page.text.count("0:29.450") >= 4
    assert "Ranked by <strong>average of the first 3 consecutive laps</strong>" in page.text
    assert "No video was kept of this run." in page.text


def test_a_run_off_the_leaderboard_stays_its_racers_own(client, ranked_event, alice, bob):
    slower = scored(ranked_event, bob, 40_000, 40_000, 40_000, model_name="b2")
    assert client.get(slower.get_absolute_url()).status_code == 302  # to log in
    client.force_login(alice)
    assert client.get(slower.get_absolute_url()).status_code == 404
    assert client.get(reverse("racing:submission-video", args=[slower.pk])).status_code == 404
    client.force_login(bob)
    page = client.get(slower.get_absolute_url())
    assert "your place on the leaderboard" in page.text and "an earlier, better run" in page.text


def test_the_submit_forms_model_list_costs_the_same_queries_however_many_models(alice, tracks):
    """Whether each ready model is untrained comes from its jobs, fetched for all at once."""
    first = ready_model(alice)
    untrained = RLModel.objects.get(pk=first.pk)

    def queries_to_show_the_list() -> tuple[int, str]:
        field = SubmissionForm(racer=alice)["model"]
        with CaptureQueriesContext(connection) as queries:
            shown = str(field)
        return len(queries), shown

    alone, _ = queries_to_show_the_list()
    for n, iteration in ((2, 3), (3, 5), (4, 0)):
        job = untrained.jobs.get()
        untrained.pk, untrained.name = None, f"copy-{n}"
        untrained.save()
        # a rolled-back test's model of the same id may have left a clone's weights, which
        # would make its iteration 0 trained: the stored files outlive the database's rows
        default_storage.delete(artifacts.path(untrained, artifacts.CLONED_WEIGHTS))
        job.pk, job.model = None, untrained
        job.last_checkpoint = f"{untrained.pk}/checkpoints/iteration-{iteration}.safetensors"
        job.save()
    many, shown = queries_to_show_the_list()
    assert many == alone
    assert f">copy-4 (Ready: {UNTRAINED})<" in shown and ">copy-3<" in shown
