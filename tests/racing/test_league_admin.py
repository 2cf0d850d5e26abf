"""Who may do what: race staff in the admin, racers in their own community races, and anyone
reading the leaderboards."""

import importlib

import pytest
from django.apps import apps as django_apps
from django.contrib.auth.models import User
from django.templatetags.static import static
from django.urls import reverse

from accounts.models import Profile
from accounts.selectors import racer_name
from notifications.models import Notification
from racing.models import Event, Racer, Ranking, Submission
from tests.helpers.accounts import PASSWORD, racer
from tests.helpers.league import DAY, event, race_staff_group, scored

pytestmark = pytest.mark.usefixtures("tracks")


@pytest.fixture
def race_staff(db) -> User:
    user = User.objects.create_user("rita", password=PASSWORD, is_staff=True)
    user.groups.add(race_staff_group())
    return user


@pytest.mark.django_db
def test_anonymous_visitors_read_leaderboards_and_standings(client, alice):
    trial = event()
    scored(trial, alice, 10_000, 10_000, 10_000)
    page = client.get(trial.get_absolute_url())
    assert page.status_code == 200 and "0:10.000" in page.text and "Watch" in page.text
    standings = client.get(reverse("racing:season-standings", args=[trial.season_id]))
    assert standings.status_code == 200 and "alice" in standings.text
    ranking = Ranking.objects.get()
    video = client.get(reverse("racing:submission-video", args=[ranking.submission_id]))
    assert video.status_code == 404  # this test's submission has no video file


@pytest.mark.django_db
def test_a_racer_cannot_change_events(client, alice):
    client.force_login(alice)
    response = client.get(reverse("admin:racing_event_add"))
    assert response.status_code == 302 and "/login/" in response.url


@pytest.mark.django_db
def test_race_staff_manage_events_but_not_users(client, race_staff):
    client.force_login(race_staff)
    assert client.get(reverse("admin:racing_event_add")).status_code == 200
    assert client.get(reverse("admin:racing_season_changelist")).status_code == 200
    assert client.get(reverse("admin:racing_livesession_changelist")).status_code == 200
    assert client.get(reverse("admin:auth_user_changelist")).status_code == 403


@pytest.mark.django_db
def test_staff_close_an_event_and_disqualify_from_the_admin(client, race_staff, alice, bob):
    trial = event()
    fast = scored(trial, alice, 9_000, 9_000, 9_000)
    scored(trial, alice, 10_000, 10_000, 10_000)
    client.force_login(race_staff)
    changelist = reverse("admin:racing_submission_changelist")
    chosen = {"action": "disqualify", "_selected_action": [fast.pk]}
    asked = client.post(changelist, chosen)
    assert asked.status_code == 200 and "Disqualify 1 submission" in asked.text
    assert 'name="reason"' in asked.text
    assert f"m by {racer_name(racer=alice)} (alice) in Time trial" in asked.text
    without_reason = client.post(changelist, {**chosen, "apply": "yes", "reason": " "})
    assert "Say why: the racer reads it." in without_reason.text
    assert Ranking.objects.get(racer=alice).score_ms == 9_000  # nothing happened yet

    done = client.post(
        changelist, {**chosen, "apply": "yes", "reason": "Cut the chicane on lap 2"}, follow=True
    )
    assert "Disqualified 1 submission." in done.text
    assert Ranking.objects.get(racer=alice).score_ms == 10_000
    fast.refresh_from_db()
    assert fast.disqualified and fast.disqualification_reason == "Cut the chicane on lap 2"
    closed = client.post(
        reverse("admin:racing_event_changelist"),
        {"action": "close_events", "_selected_action": [trial.pk]},
        follow=True,
    )
    assert "Closed 1 event." in closed.text
    assert Event.objects.get(pk=trial.pk).state == Event.State.CLOSED
    changelist = client.get(reverse("admin:racing_submission_change", args=[fast.pk]))
    assert changelist.status_code == 200 and "Laps" in changelist.text


@pytest.mark.django_db
def test_a_staff_division_change_is_kept_from_the_monthly_promotion(client, race_staff, alice):
    racer = Racer.of(alice)
    client.force_login(race_staff)
    response = client.post(
        reverse("admin:racing_racer_change", args=[racer.pk]), {"division": "PRO"}
    )
    assert response.status_code == 302
    racer.refresh_from_db()
    assert racer.division == "PRO" and racer.division_set_by_staff


def test_staff_set_the_division_of_a_racer_who_never_opened_a_race_page(client, race_staff):
    vera = racer("vera")
    Profile.objects.filter(user=vera).update(racer_name="VeraFast")
    client.force_login(race_staff)
    found = client.get(reverse("admin:racing_racer_changelist"), {"q": "VeraFast"}).text
    assert "VeraFast" in found  # a row from sign-up, found by the racer name
    league = Racer.objects.get(user=vera)
    change = reverse("admin:racing_racer_change", args=[league.pk])
    assert client.post(change, {"division": "PRO"}).status_code == 302
    league.refresh_from_db()
    assert league.division == "PRO" and league.division_set_by_staff


# Community races


@pytest.mark.django_db
def test_the_race_form_keeps_what_was_typed_and_says_what_to_change(client, alice):
    client.force_login(alice)
    response = client.post(
        reverse("racing:community-race-create"),
        {
            "name": "Backwards",
            "track": "",
            "race_type": "TIME_TRIAL",
            "ranking_method": "BEST_LAP",
            "opens_at": "2026-02-01T00:00",
            "closes_at": "2026-01-01T00:00",
            "laps_required": 3,
            "laps_to_drive": 2,
            "off_track_penalty_s": 1,
            "crash_penalty_s": 2,
            "submissions_per_racer": 5,
        },
    )
    assert response.status_code == 200
    assert 'value="Backwards"' in response.text
    errors = response.context["form"].errors
    assert "track" in errors
    assert errors["closes_at"] == ["An event closes after it opens."]
    assert errors["laps_to_drive"] == ["Drive at least the 3 consecutive laps that qualify."]
    assert not Event.objects.filter(name="Backwards").exists()


@pytest.mark.django_db
def test_a_private_race_is_entered_through_its_invitation(client, community_race, alice, bob):
    assert not community_race.public and community_race.organiser == alice
    assert client.get(community_race.get_absolute_url()).status_code == 404
    client.force_login(bob)
    assert client.get(community_race.get_absolute_url()).status_code == 404
    invite = reverse("racing:event-join", args=[community_race.invite_token])
    assert "Join the race" in client.get(invite).text
    response = client.post(invite)
    assert response.status_code == 302
    assert client.get(community_race.get_absolute_url()).status_code == 200
    assert community_race.participants.filter(pk=bob.pk).exists()
    assert client.get(reverse("racing:event-join", args=["not-a-token"])).status_code == 404


@pytest.mark.django_db
def test_the_organiser_removes_a_racer_and_closes_the_race_early(
    client, community_race, alice, bob
):
    community_race.participants.add(bob)
    scored(community_race, bob, 10_000)
    client.force_login(bob)
    assert (
        client.get(reverse("racing:community-race-manage", args=[community_race.slug])).status_code
        == 404
    )
    client.force_login(alice)
    manage = client.get(reverse("racing:community-race-manage", args=[community_race.slug]))
    assert community_race.invite_token in manage.text
    client.post(reverse("racing:community-race-remove", args=[community_race.slug, bob.pk]))
    assert not community_race.participants.filter(pk=bob.pk).exists()
    assert not Ranking.objects.filter(event=community_race).exists()
    assert Submission.objects.filter(event=community_race, racer=bob).exists()  # history stays

    client.post(reverse("racing:community-race-close", args=[community_race.slug]))
    community_race.refresh_from_db()
    assert community_race.state == Event.State.CLOSED
    client.force_login(bob)
    expired = client.get(reverse("racing:event-join", args=[community_race.invite_token]))
    assert expired.status_code == 410 and "expired when the race closed" in expired.text
    client.post(reverse("racing:event-join", args=[community_race.invite_token]))
    assert not community_race.participants.filter(pk=bob.pk).exists()


@pytest.mark.django_db
def test_season_standings_give_points_by_place_per_division(client, alice, bob, stella):
    first = event("First")
    second = event("Second")
    scored(first, alice, 9_000, 9_000, 9_000)
    scored(first, bob, 10_000, 10_000, 10_000)
    scored(second, bob, 9_000, 9_000, 9_000)
    scored(second, alice, 10_000, 10_000, 10_000)
    scored(second, stella, 11_000, 11_000, 11_000)
    event("Pro one", division="PRO")
    response = client.get(reverse("racing:season-standings", args=[first.season_id]))
    rows = [(s.position, s.racer, s.points, s.finishes) for s in response.context["standings"]]
    # 25 + 18 each: countback sorts them by name then (both have a first and a second place)
    assert rows == [(1, alice, 43, [1, 2]), (2, bob, 43, [1, 2]), (3, stella, 15, [3])]
    pro = client.get(reverse("racing:season-standings", args=[first.season_id]) + "?division=PRO")
    assert pro.context["standings"] == [] and "No points yet in the Pro division" in pro.text


@pytest.mark.django_db
def test_an_upcoming_event_can_be_closed_before_it_opens(alice):
    from racing import services

    later = event("Later", opens=DAY, closes=2 * DAY)
    services.event_close(event=later)
    assert later.state == Event.State.CLOSED


@pytest.mark.django_db
def test_a_disqualified_racer_is_told_why_and_reads_it_on_their_runs_page(
    client, race_staff, alice
):
    trial = event()
    run = scored(trial, alice, 9_000, 9_000, 9_000)
    client.force_login(race_staff)
    client.post(
        reverse("admin:racing_submission_changelist"),
        {
            "action": "disqualify",
            "_selected_action": [run.pk],
            "apply": "yes",
            "reason": "Cut the chicane on lap 2",
        },
    )
    told = Notification.objects.get(recipient=alice, text__contains="disqualified")
    assert told.text == (
        "m in Time trial was disqualified by the league staff: Cut the chicane on lap 2. "
        "It no longer counts on the leaderboard."
    )
    assert told.url == run.get_absolute_url()
    client.force_login(alice)
    page = client.get(run.get_absolute_url())
    assert (
        "Disqualified: Cut the chicane on lap 2" in page.text and "data-disqualified" in page.text
    )


def _laps_inline(run: Submission) -> dict:
    """The submission admin page's laps inline, as the page posts it back unchanged."""
    return {"laps-TOTAL_FORMS": 3, "laps-INITIAL_FORMS": 3} | {
        f"laps-{n}-{name}": value
        for n, lap in enumerate(run.laps.all())
        for name, value in (("id", lap.pk), ("submission", run.pk))
    }


@pytest.mark.django_db
def test_disqualifying_on_a_submissions_admin_page_asks_why_and_tells_the_racer(
    client, race_staff, alice
):
    run = scored(event(), alice, 9_000, 9_000, 9_000)
    client.force_login(race_staff)
    change = reverse("admin:racing_submission_change", args=[run.pk])
    laps = _laps_inline(run)
    refused = client.post(change, {**laps, "disqualified": "on", "disqualification_reason": ""})
    assert "Say why: the racer reads it." in refused.text
    assert not Submission.objects.get(pk=run.pk).disqualified

    client.post(change, {**laps, "disqualified": "on", "disqualification_reason": "Wrong car"})
    assert Submission.objects.get(pk=run.pk).disqualified
    assert not Ranking.objects.filter(racer=alice).exists()
    assert Notification.objects.get(recipient=alice, text__contains="disqualified").text.startswith(
        "m in Time trial was disqualified by the league staff: Wrong car."
    )


@pytest.mark.django_db
def test_reinstating_on_a_submissions_admin_page_clears_the_reason_and_announces_it(
    client, race_staff, alice, monkeypatch
):
    from racing import broadcasts

    run = scored(event(), alice, 9_000, 9_000, 9_000)
    client.force_login(race_staff)
    change = reverse("admin:racing_submission_change", args=[run.pk])
    laps = _laps_inline(run)
    client.post(change, {**laps, "disqualified": "on", "disqualification_reason": "Wrong car"})
    announced = []
    monkeypatch.setattr(broadcasts, "announce_leaderboard", announced.append)
    saved = client.post(change, {**laps, "disqualification_reason": "Wrong car"})
    assert saved.status_code == 302
    run.refresh_from_db()
    assert (run.disqualified, run.disqualification_reason) == (False, "")
    assert Ranking.objects.get(racer=alice).submission == run
    assert announced == [run.event]


@pytest.mark.django_db
def test_the_admin_shows_the_sites_icon_and_favicon_ico_finds_it(client, race_staff):
    client.force_login(race_staff)
    admin_page = client.get(reverse("admin:index"))
    icon = static("console/pitlane.svg")
    assert f'<link rel="icon" href="{icon}" type="image/svg+xml">' in admin_page.text
    assert "Pitlane administration" in admin_page.text  # the admin's own header stays
    favicon = client.get("/favicon.ico")
    assert favicon.status_code == 302 and favicon.url == icon
    assert client.get(icon)["Content-Type"].startswith("image/svg+xml")


def test_the_migration_gives_every_older_account_its_division(alice, bob):
    Racer.objects.filter(user=alice).delete()  # an account made before sign-up made the row
    migration = importlib.import_module("racing.migrations.0011_event_divisions_and_winner")
    migration.racer_rows(django_apps, None)
    migration.racer_rows(django_apps, None)  # run again: nothing more
    assert Racer.objects.filter(user=alice, division="OPEN").count() == 1
    assert Racer.objects.filter(user=bob).count() == 1
