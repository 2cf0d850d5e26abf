"""Submitting, scoring and ranking: eligibility, the race itself, rankings under concurrency,
disqualification, the monthly promotion, and the live leaderboard."""

import asyncio
import re
import threading
from datetime import date, datetime, timedelta

import pytest
from asgiref.sync import sync_to_async
from django.core.files.storage import default_storage
from django.db import connection
from django.urls import reverse
from django.utils import timezone

from jobs import evaluation as evaluations
from racing import selectors, services
from racing.models import Division, Event, Racer, RaceType, Ranking, Submission
from tests.helpers.evaluations import trial_paths
from tests.helpers.league import DAY, event, race_evaluation, scored
from tests.helpers.live import viewer
from tests.helpers.models import ready_model, with_a_later_checkpoint
from training.models import EvaluationJob, RLModel

pytestmark = pytest.mark.usefixtures("tracks")


# Eligibility


@pytest.mark.django_db
def test_a_racer_submits_only_their_own_ready_models_to_open_events_of_their_division(alice, bob):
    trial = event()
    mine = ready_model(alice)
    theirs = ready_model(bob, name="bobs")
    assert "only your own models" in selectors.submission_refusal(
        racer=alice, event=trial, model=theirs
    )
    closed = event("Closed", opens=-2 * DAY, closes=-DAY)
    assert "has closed" in selectors.submission_refusal(racer=alice, event=closed, model=mine)
    upcoming = event("Later", opens=DAY, closes=2 * DAY)
    assert "opens on" in selectors.submission_refusal(racer=alice, event=upcoming, model=mine)
    pro = event("Pro trial", division=Division.PRO)
    assert "Pro event and you race in the Open division" in selectors.submission_refusal(
        racer=alice, event=pro, model=mine
    )
    assert selectors.submission_refusal(racer=alice, event=trial, model=mine) is None

    RLModel.objects.filter(pk=mine.pk).update(status=RLModel.Status.TRAINING)
    with pytest.raises(services.SubmissionRefused, match="is training"):
        services.submission_create(racer=alice, event=trial, model=mine)
    assert not Submission.objects.exists()


@pytest.mark.django_db
def test_the_submission_limit_counts_all_but_failures(alice):
    trial = event(submissions_per_racer=2)
    model = ready_model(alice)
    first = services.submission_create(racer=alice, event=trial, model=model)
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.SUBMITTING
    assert first.evaluation.continuous_laps and first.evaluation.trials == trial.laps_to_drive
    Submission.objects.filter(pk=first.pk).update(status=Submission.Status.FAILED)
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.READY)
    services.submission_create(racer=alice, event=trial, model=model)
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.READY)
    services.submission_create(racer=alice, event=trial, model=model)
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.READY)
    with pytest.raises(services.SubmissionRefused, match="your 2 submissions"):
        services.submission_create(racer=alice, event=trial, model=model)


def chosen(page, name: str) -> list[str]:
    """The values of the options selected in the page's ``name`` select (an event's and a
    model's ids may be the same number)."""
    select = re.search(rf'<select name="{name}"[^>]*>(.*?)</select>', page.text, re.S)
    assert select, f"no {name} select"
    return re.findall(r'<option value="([^"]*)" selected>', select.group(1))


@pytest.mark.django_db
def test_the_submit_page_keeps_the_choice_and_says_why_it_is_refused(client, alice):
    model = ready_model(alice)
    pro = event("Pro trial", division=Division.PRO)
    client.force_login(alice)
    page = client.get(reverse("racing:submission-create"))
    assert "No event is open to you right now" in page.text
    trial = event()
    page = client.get(reverse("racing:submission-create"))  # the only event, the only model
    assert chosen(page, "event") == [str(trial.pk)]
    assert chosen(page, "model") == [str(model.pk)]
    other = ready_model(alice, name="other")
    page = client.get(reverse("racing:submission-create") + f"?model={other.pk}")
    assert page.status_code == 200 and "Pro trial" not in page.text  # not offered
    assert chosen(page, "model") == [str(other.pk)]
    response = client.post(
        reverse("racing:submission-create"), {"event": pro.pk, "model": model.pk}
    )
    assert response.status_code == 200
    assert "Choose one of the open events listed." in response.text
    assert chosen(response, "model") == [str(model.pk)]
    response = client.post(
        reverse("racing:submission-create"),
        {"event": trial.pk, "model": model.pk, "checkpoint": "last"},
    )
    submission = Submission.objects.get()
    assert response.status_code == 302 and response.url == submission.get_absolute_url()
    assert submission.checkpoint == submission.evaluation.checkpoint == "last"
    detail = client.get(submission.get_absolute_url())
    assert "Queued" in detail.text and "Watch it race live" in detail.text
    assert client.get(reverse("racing:submission-list")).text.count(trial.name) == 1


# The race


@pytest.mark.django_db
def test_an_off_track_limit_per_lap_leaves_the_car_unqualified_but_shown(client, alice):
    trial = event(max_off_tracks_per_lap=1)
    # Laps 1 and 3 are within the limit, lap 2 is not: no 3 consecutive laps count.
    submission = scored(trial, alice, 9_000, 9_000, 9_000, off_tracks=(1, 2, 0))
    assert submission.status == Submission.Status.COMPLETED and not submission.qualified
    assert [lap.counted for lap in submission.laps.order_by("number")] == [True, False, True]
    assert not Ranking.objects.exists()
    client.force_login(alice)
    page = client.get(submission.get_absolute_url())
    assert "Not ranked: fewer than 3 consecutive complete laps" in page.text
    assert page.text.count("Not counted: over 1 off-track") == 1


@pytest.mark.django_db
def test_a_race_whose_model_lost_its_weights_fails_and_the_model_is_ready_again(alice):
    trial = event()
    model = ready_model(alice)
    submission = services.submission_create(racer=alice, event=trial, model=model)
    model.jobs.update(best_checkpoint="", last_checkpoint="")
    services.submission_run(submission_id=submission.pk)
    submission.refresh_from_db()
    assert submission.status == Submission.Status.FAILED
    assert "no trained weights" in submission.failure_reason
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY
    assert selectors.submissions_counted(racer=alice, event=trial) == 0


# Rankings


@pytest.mark.django_db
def test_a_worse_resubmission_does_not_replace_and_a_better_one_does(alice):
    trial = event()
    first = scored(trial, alice, 10_000, 10_000, 10_000)
    scored(trial, alice, 12_000, 12_000, 12_000)
    assert Ranking.objects.get().submission_id == first.pk
    scored(trial, alice, 10_000, 10_000, 10_000)  # equal, later: the earlier keeps it
    assert Ranking.objects.get().submission_id == first.pk
    better = scored(trial, alice, 9_000, 9_000, 9_000)
    assert Ranking.objects.get().submission_id == better.pk
    assert Ranking.objects.count() == 1


@pytest.mark.django_db
def test_ties_go_to_the_earlier_submission_even_when_it_is_scored_later(alice, bob):
    trial = event()
    now = timezone.now()
    scored(trial, bob, 10_000, 10_000, 10_000, at=now - timedelta(minutes=1))
    later = scored(trial, alice, 10_000, 10_000, 10_000, at=now)
    earlier = scored(trial, alice, 10_000, 10_000, 10_000, at=now - timedelta(minutes=5))
    assert Ranking.objects.get(racer=alice).submission_id == earlier.pk != later.pk
    page = selectors.leaderboard_page(event=trial)
    assert [(r.racer.username, r.position, r.gap_ms) for r in page] == [
        ("alice", 1, 0),
        ("bob", 2, 0),
    ]


@pytest.mark.django_db
def test_a_disqualification_gives_the_racers_next_best_its_place(client, alice, bob):
    trial = event()
    scored(trial, alice, 12_000, 12_000, 12_000)
    best = scored(trial, alice, 9_000, 9_000, 9_000)
    only = scored(trial, bob, 11_000, 11_000, 11_000)
    services.submission_disqualify(submission=best, reason="Cut the chicane")
    assert Ranking.objects.get(racer=alice).score_ms == 12_000
    services.submission_disqualify(submission=only, reason="Cut the chicane")
    assert not Ranking.objects.filter(racer=bob).exists()
    client.force_login(alice)
    assert "Disqualified: Cut the chicane" in client.get(reverse("racing:submission-list")).text


@pytest.mark.django_db(transaction=True)
def test_two_scorings_that_finish_at_once_leave_the_better_one_ranked(alice):
    trial = event()
    submissions = [
        Submission.objects.create(event=trial, racer=alice, model_name=name)
        for name in ("slow", "fast")
    ]
    scores = {"slow": 12_000, "fast": 9_000}
    for submission in submissions:
        Submission.objects.filter(pk=submission.pk).update(
            score_ms=scores[submission.model_name], qualified=True
        )
        submission.refresh_from_db()
    start = threading.Barrier(2)
    errors = []

    def offer(submission):
        try:
            start.wait()
            services.ranking_offer(submission=submission)
        except Exception as error:
            errors.append(error)
        finally:
            connection.close()

    for _ in range(5):  # in both orders, several times
        Ranking.objects.all().delete()
        threads = [threading.Thread(target=offer, args=(s,)) for s in submissions]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        submissions.reverse()
        assert not errors
        assert list(Ranking.objects.values_list("model_name", "score_ms")) == [("fast", 9_000)]


@pytest.mark.django_db
def test_event_rankings_recompute_from_the_submissions(alice, bob):
    trial = event()
    scored(trial, alice, 10_000, 10_000, 10_000)
    scored(trial, bob, 11_000, None, 11_000, 11_000, 11_000)
    Ranking.objects.all().delete()
    assert services.event_rankings_recompute(event=trial) == 2
    assert list(trial.rankings.values_list("racer__username", "score_ms")) == [
        ("alice", 10_000),
        ("bob", 11_000),
    ]


@pytest.mark.django_db
def test_a_leaderboard_pages_by_a_hundred_and_shows_the_racers_own_place(client, alice):
    from django.contrib.auth.models import User

    trial = event()
    racers = User.objects.bulk_create([User(username=f"r{i:03d}") for i in range(150)])
    for i, racer in enumerate(racers):
        scored(trial, racer, 10_000 + i, 10_000 + i, 10_000 + i)
    scored(trial, alice, 20_000, 20_000, 20_000)
    client.force_login(alice)
    first = client.get(trial.get_absolute_url())
    assert first.context["page"].paginator.count == 151
    assert len(first.context["rankings"]) == 100
    assert "Your place, on" in first.text and 'href="?page=2"' in first.text
    second = client.get(trial.get_absolute_url() + "?page=2")
    assert [r.position for r in second.context["rankings"]][-1] == 151
    assert second.context["rankings"][-1].gap_ms == 10_000
    assert '<tr class="mine">' in second.text and "Your place, on" not in second.text


# Divisions


@pytest.mark.django_db
def test_the_monthly_promotion_moves_the_top_tenth_of_last_months_open_time_trials_up(
    alice, bob, stella
):
    from django.contrib.auth.models import User

    last_month = event("October trial", opens=-60 * DAY, closes=-40 * DAY)
    Event.objects.filter(pk=last_month.pk).update(
        opens_at=timezone.make_aware(datetime(2026, 10, 1)),
        closes_at=timezone.make_aware(datetime(2026, 11, 1)) - timedelta(seconds=1),
    )
    racers = [alice, bob, *User.objects.bulk_create([User(username=f"r{i}") for i in range(18)])]
    for place, racer in enumerate(racers):
        scored(last_month, racer, 10_000 + place, 10_000 + place, 10_000 + place)
    Racer.objects.filter(user=bob).update(division_set_by_staff=True)  # staff keep bob in Open

    promoted = services.divisions_promote(today=date(2026, 11, 1))
    assert [racer.user.username for racer in promoted] == ["alice"]
    assert Racer.of(alice).division == Division.PRO and Racer.of(alice).promoted_at
    assert Racer.of(bob).division == Division.OPEN
    assert services.divisions_promote(today=date(2026, 11, 1)) == []
    assert services.divisions_promote(today=date(2026, 12, 1)) == []  # a month later: none


@pytest.mark.django_db
def test_a_pro_racer_enters_pro_events_and_not_open_ones(alice):
    Racer.objects.filter(user=alice).update(division=Division.PRO)
    model = ready_model(alice)
    avoidance = event(
        "Pro boxes",
        division=Division.PRO,
        race_type=RaceType.OBJECT_AVOIDANCE,
        boxes={"count": 2, "randomize": False},
    )
    assert selectors.submission_refusal(racer=alice, event=avoidance, model=model) is None
    assert "Pro racers enter Pro events" in selectors.submission_refusal(
        racer=alice, event=event(), model=model
    )


@pytest.mark.django_db
def test_an_event_open_to_both_divisions_takes_either_without_moving_anyone(alice, bob):
    Racer.objects.filter(user=alice).update(division=Division.PRO)
    shared = event("Club night", any_division=True)
    only_open = event("Open only")
    for racer in (alice, bob):
        model = ready_model(racer)
        assert selectors.submission_refusal(racer=racer, event=shared, model=model) is None
        assert shared in selectors.events_open_to(racer=racer)
    assert only_open not in selectors.events_open_to(racer=alice)
    assert [Racer.of(alice).division, Racer.of(bob).division] == [Division.PRO, Division.OPEN]


@pytest.mark.django_db
def test_an_open_event_is_a_time_trial(tracks):
    from django.core.exceptions import ValidationError

    with pytest.raises(ValidationError, match="Open events are time trials"):
        event("Boxes", race_type=RaceType.OBJECT_AVOIDANCE)
    with pytest.raises(ValidationError, match="at least the 3 consecutive laps"):
        event("Short", laps_to_drive=2)


# Live


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
async def test_a_leaderboard_hears_when_a_submission_is_scored(alice):
    trial = await sync_to_async(event)()
    communicator = await viewer(f"/ws/events/{trial.pk}/")  # anonymous: public event
    connected, _ = await communicator.connect()
    assert connected
    # Idle past the channel layer's 5 s blocking read: with redis-py 8's default socket timeout
    # the consumer died here, and the page heard nothing more.
    await asyncio.sleep(7)
    submission = await sync_to_async(scored)(trial, alice, 10_000, 10_000, 10_000)
    message = await communicator.receive_json_from(timeout=5)
    assert message == {
        "type": "submission",
        "event": trial.pk,
        "submission": submission.pk,
        "status": "COMPLETED",
        "status_display": "Completed",
        "score_ms": 10_000,
        "qualified": True,
        "ranked": True,
    }
    await communicator.disconnect()


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
async def test_a_submission_races_under_the_events_rules_on_a_real_worker(
    alice, celery_worker_process
):
    trial = await sync_to_async(event)(off_track_penalty_s=1.0, laps_required=2, laps_to_drive=3)
    model = await sync_to_async(ready_model)(alice)
    communicator = await viewer(f"/ws/events/{trial.pk}/")
    connected, _ = await communicator.connect()
    assert connected
    submission = await sync_to_async(services.submission_create)(
        racer=alice, event=trial, model=model
    )
    message = await communicator.receive_json_from(timeout=60)
    assert (message["submission"], message["status"]) == (submission.pk, "IN_PROGRESS")
    while not message.get("ranked"):  # the race runs on the worker while the page waits
        message = await communicator.receive_json_from(timeout=240)
    assert (message["submission"], message["status"]) == (submission.pk, "COMPLETED")
    await communicator.disconnect()
    assert await Ranking.objects.filter(event=trial, submission=submission).aexists()
    await sync_to_async(_assert_raced_under_the_rules)(submission.pk, trial, model)


def _assert_raced_under_the_rules(pk: int, trial: Event, model: RLModel) -> None:
    submission = Submission.objects.get(pk=pk)
    assert submission.status == Submission.Status.COMPLETED and submission.qualified
    assert submission.evaluation.status == EvaluationJob.Status.COMPLETED
    laps = list(submission.laps.all())
    assert [lap.number for lap in laps] == [1, 2, 3]  # the event's laps to drive
    for lap in laps:  # straight ahead: off at each bend, put back, 1 s each time
        assert lap.counted and lap.off_tracks > 0 and lap.penalty_ms == lap.off_tracks * 1000
    assert submission.score_ms == round((laps[0].time_ms + laps[1].time_ms) / 2)  # 2 required
    ranking = Ranking.objects.get(event=trial, racer=submission.racer)
    assert (ranking.submission_id, ranking.score_ms, ranking.laps_completed) == (
        submission.pk,
        submission.score_ms,
        3,
    )
    assert ranking.off_tracks == sum(lap.off_tracks for lap in laps)
    assert default_storage.exists(submission.video) and submission.video.startswith("league/")
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY
    assert services.submission_run(submission_id=submission.pk) is None  # never twice


# The checkpoint that races, and the seed that replays it


@pytest.mark.slow
@pytest.mark.django_db
def test_a_race_drives_the_checkpoint_chosen_and_keeps_it_and_its_seed(client, alice):
    trial = event(laps_required=1, laps_to_drive=1)
    model = with_a_later_checkpoint(ready_model(alice))
    submission = services.submission_create(
        racer=alice, event=trial, model=model, checkpoint="last"
    )
    assert submission.evaluation.checkpoint == submission.checkpoint == "last"
    assert submission.seed == submission.evaluation.seed is not None
    services.submission_run(submission_id=submission.pk)
    submission.refresh_from_db()
    assert submission.status == Submission.Status.COMPLETED
    assert submission.checkpoint_iteration == submission.evaluation.checkpoint_iteration == 2
    client.force_login(alice)
    page = client.get(submission.get_absolute_url()).text
    assert f"Last checkpoint (iteration 2) · seed {submission.seed}" in page
    model_page = client.get(reverse("training:model-detail", args=[model.pk])).text
    assert f"Last checkpoint (iteration 2) · seed {submission.seed}" in model_page

    # The same seed, the same rules and checkpoint: the same race, row for row.
    replay = race_evaluation(model, trial, checkpoint="last", seed=submission.seed)
    evaluations.run(replay.pk)
    assert trial_paths(replay) == trial_paths(submission.evaluation)
    assert [lap.time_ms for lap in submission.laps.all()] == [
        trial.time_ms for trial in replay.trial_rows.all()
    ]


@pytest.mark.django_db
def test_a_race_entry_names_a_checkpoint_the_model_has(alice):
    with pytest.raises(services.SubmissionRefused, match="best or its last checkpoint"):
        services.submission_create(
            racer=alice, event=event(), model=ready_model(alice), checkpoint="newest"
        )
