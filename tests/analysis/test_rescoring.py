"""Another reward function run over recorded driving, in the sandbox, step by step with the params
each step was given; a hostile one fails with words that say where, and touches nothing."""

from __future__ import annotations

from datetime import timedelta

import numpy as np
import pytest
from django.urls import reverse
from django.utils import timezone

from analysis import rescoring, services, summaries
from analysis.models import Rescoring, TraceSummary
from analysis.records import Source
from analysis.tasks import RESCORE_HARD_LIMIT
from tests.helpers.analysis import SPEED_AND_OFF_TRACK, recorded_by_hand
from training.models import RewardFunction

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def rescored(owner, source_code: str) -> Rescoring:
    job = recorded_by_hand(owner)
    asked = services.rescoring_create(
        source=Source.of_job(job), owner=owner, reward_function=source_code, first=None, last=None
    )
    rescoring.run(asked.pk)
    asked.refresh_from_db()
    return asked


def test_a_reward_function_scores_every_recorded_step_with_its_params(alice):
    done = rescored(alice, SPEED_AND_OFF_TRACK)
    assert done.status == Rescoring.Status.DONE, done.failure
    assert (done.first, done.last, done.steps, done.total_steps) == (1, 1, 5, 5)
    # Speeds 1, 2, 2 on the lap; 0.5, 0.5 off the track, its last step off it.
    assert done.episodes == {"1": [[0, 10.0], [1, 102.0]]}
    new = np.frombuffer(bytes(done.points), dtype=np.float32)
    assert new.tolist() == [2.0, 4.0, 4.0, 1.0, 101.0]  # the map's points, in their order
    assert done.point_counts == {"1": 5}
    assert done.log == ["waypoints: 111", "waypoints: 111"]  # printed at each episode's step 2


@pytest.mark.slow
@pytest.mark.parametrize(
    ("code", "said"),
    [
        (
            "def reward_function(params):\n    return float(open('/etc/hostname').read())\n",
            "Iteration 1, episode 0, step 2, line 2:",
        ),
        ("def reward_function(params):\n    while True:\n        pass\n", "took longer than 1 s"),
        (
            "def reward_function(params):\n    return params['no_such_param']\n",
            "Iteration 1, episode 0, step 2, line 2: KeyError",
        ),
        ("def reward_function(params)\n    return 1.0\n", "did not load"),
    ],
    ids=["reads a file", "never returns", "a param DeepRacer has not", "not Python"],
)
def test_a_reward_function_that_fails_says_where(alice, code, said):
    failed = rescored(alice, code)
    assert failed.status == Rescoring.Status.FAILED
    assert said in failed.failure
    assert failed.episodes == {} and bytes(failed.points) == b""


def test_a_rescoring_runs_once_however_often_it_is_delivered(alice):
    done = rescored(alice, SPEED_AND_OFF_TRACK)
    finished = done.finished_at
    rescoring.run(done.pk)  # a redelivery: nothing happens
    done.refresh_from_db()
    assert done.status == Rescoring.Status.DONE and done.finished_at == finished


def test_the_page_asks_for_a_rescoring_and_refuses_what_cannot_run(alice, client, monkeypatch):
    job = recorded_by_hand(alice)
    client.force_login(alice)
    base = reverse("analysis:model", args=[job.model.pk])
    empty = client.post(f"{base}rescore/", {"reward_function": ""})
    assert empty.status_code == 400
    assert empty.json()["errors"]["reward_function"][0]["message"].startswith("Paste a reward")
    past = client.post(f"{base}rescore/", {"reward_function": SPEED_AND_OFF_TRACK, "first": 4})
    assert past.status_code == 400
    assert past.json()["errors"]["first"][0]["message"] == (
        "No iteration from 4 to 4 was recorded; iterations 1 to 1 were."
    )
    backwards = {"reward_function": SPEED_AND_OFF_TRACK, "first": 3, "last": 2}
    assert "comes before" in str(client.post(f"{base}rescore/", backwards).json())
    monkeypatch.setattr(services, "MAX_RESCORE_STEPS", 4)
    big = client.post(f"{base}rescore/", {"reward_function": SPEED_AND_OFF_TRACK, "first": 1})
    assert "hold 5 steps; a re-scoring takes at most 4" in str(big.json())
    monkeypatch.undo()
    asked = client.post(f"{base}rescore/", {"reward_function": SPEED_AND_OFF_TRACK})
    assert asked.status_code == 202
    assert asked.json()["status"] == "QUEUED"
    followed = client.get(asked.json()["url"]).json()
    assert followed["id"] == asked.json()["id"] and followed["total_steps"] == 5
    # A range past what was recorded scores what was: iteration 1 alone.
    wide = {"reward_function": SPEED_AND_OFF_TRACK, "first": 0, "last": 2**40}
    scored = client.post(f"{base}rescore/", wide).json()
    assert (scored["first"], scored["last"], scored["total_steps"]) == (1, 1, 5)


def test_a_racer_rescores_with_the_models_own_or_a_saved_function_and_never_anothers(
    alice, bob, client
):
    job = recorded_by_hand(alice)
    mine = RewardFunction.objects.create(owner=alice, name="speedy", source=SPEED_AND_OFF_TRACK)
    theirs = RewardFunction.objects.create(owner=bob, name="secret", source="def nope(")
    client.force_login(alice)
    base = reverse("analysis:model", args=[job.model.pk])
    page = client.get(base).content.decode()
    assert '<option value="model" selected>' in page and ">speedy</option>" in page
    assert "secret" not in page

    asked = client.post(f"{base}rescore/", {"saved": mine.pk, "reward_function": ""})
    assert asked.status_code == 202
    assert Rescoring.objects.get(pk=asked.json()["id"]).reward_function == SPEED_AND_OFF_TRACK
    own = client.post(f"{base}rescore/", {"saved": "model", "reward_function": "ignored"})
    assert Rescoring.objects.get(pk=own.json()["id"]).reward_function == job.model.reward_function

    refused = client.post(f"{base}rescore/", {"saved": theirs.pk, "reward_function": ""})
    assert refused.status_code == 400
    said = refused.json()["errors"]["saved"][0]["message"]
    assert said.startswith("Choose the model's own reward function or one of your saved ones")
    assert Rescoring.objects.filter(reward_function=theirs.source).count() == 0


def test_a_rescoring_whose_worker_died_fails_and_frees_its_place(alice, client):
    source = Source.of_job(recorded_by_hand(alice))

    def ask() -> Rescoring:
        return services.rescoring_create(
            source=source, owner=alice, reward_function=SPEED_AND_OFF_TRACK, first=None, last=None
        )

    dead, alive, _ = (ask() for _ in range(services.MAX_RESCORINGS_AT_ONCE))
    with pytest.raises(services.RescoringRefused, match="Wait for your re-scorings"):
        ask()
    # One's worker was killed past the task's time limit; the other's is still scoring.
    long_ago = timezone.now() - timedelta(seconds=RESCORE_HARD_LIMIT + services.LAPSE_MARGIN + 1)
    Rescoring.objects.filter(pk=dead.pk).update(
        status=Rescoring.Status.RUNNING, started_at=long_ago
    )
    Rescoring.objects.filter(pk=alive.pk).update(
        status=Rescoring.Status.RUNNING, started_at=timezone.now()
    )
    client.force_login(alice)
    base = reverse("analysis:model", args=[source.model.pk])
    page = client.get(base).text  # its list says the dead one failed, before any poll
    listed = page.split(f'rescorings/{dead.pk}/">', 1)[1].split("</li>", 1)[0]
    assert "· Failed ·" in listed, listed
    told = client.get(f"{base}rescorings/{dead.pk}/").json()
    assert told["status"] == "FAILED" and told["failure"] == (
        "The worker scoring it stopped answering; ask for it again."
    )
    assert client.get(f"{base}rescorings/{alive.pk}/").json()["status"] == "RUNNING"
    assert ask().status == Rescoring.Status.QUEUED  # the dead one's place is free again
    rescoring.run(dead.pk)  # its task, delivered again at last: nothing happens
    assert Rescoring.objects.get(pk=dead.pk).status == Rescoring.Status.FAILED


def test_the_map_colours_by_the_new_reward_beside_the_old(alice, client):
    done = rescored(alice, SPEED_AND_OFF_TRACK)
    client.force_login(alice)
    base = reverse("analysis:model", args=[done.job.model.pk])
    data = client.get(f"{base}points.bin?rescoring={done.pk}").content
    points = np.frombuffer(data, dtype="<f4").reshape(len(summaries.POINT_COLUMNS) + 2, -1)
    old = points[summaries.POINT_COLUMNS.index("reward")]
    assert old.tolist() == pytest.approx([1.0, 2.0, 3.0, 0.5, 0.001])
    assert points[-1].tolist() == [2.0, 4.0, 4.0, 1.0, 101.0]
    assert TraceSummary.objects.filter(job=done.job).count() == 1
