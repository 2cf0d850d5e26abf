"""Evaluations: the command, the task on a real worker, the pages, the files and the video."""

import csv
import io
import itertools
import json
import tempfile
from datetime import timedelta

import cv2
import numpy as np
import pytest
from asgiref.sync import sync_to_async
from django.core.files.storage import default_storage
from django.core.management import CommandError, call_command
from django.urls import reverse
from django.utils import timezone

from analysis.models import TraceSummary
from common.every import Every
from jobs import evaluation as evaluations
from jobs.evaluation import EvaluationFailed, _VideoWriter
from tests.helpers.evaluations import stored, trial_paths
from tests.helpers.live import frame_header, viewer
from tests.helpers.models import ready_model, trained_model
from tests.helpers.training_logs import EVALUATION_KEYS, assert_evaluation_logs_read_as_recorded
from tests.services import wait_for
from training import configuration, leases, services, signals
from training.artifacts import EVALUATION_METRICS as METRICS
from training.artifacts import EVALUATION_TRACE as TRACE
from training.artifacts import EVALUATION_VIDEO as VIDEO
from training.models import EvaluationJob, RLModel

pytestmark = pytest.mark.usefixtures("tracks")

STEP_MS = 1000 / 15


def decoded_frames(data: bytes) -> tuple[int, tuple[int, int]]:
    with tempfile.NamedTemporaryFile(suffix=".webm") as handle:
        handle.write(data)
        handle.flush()
        capture = cv2.VideoCapture(handle.name)
        count, size = 0, None
        while True:
            ok, image = capture.read()
            if not ok:
                break
            count, size = count + 1, (image.shape[1], image.shape[0])
        capture.release()
    return count, size


@pytest.mark.slow
@pytest.mark.django_db
def test_the_evaluate_command_prints_the_results_and_records_every_step(alice, capsys):
    model = ready_model(alice)
    call_command("evaluate", model.name, "--track", "pitlane-oval", "--trials", "3")
    printed = capsys.readouterr().out

    evaluation = EvaluationJob.objects.get(model=model)
    assert evaluation.status == EvaluationJob.Status.COMPLETED
    trials = list(evaluation.trial_rows.all())
    assert [t.number for t in trials] == [1, 2, 3]
    for trial in trials:  # straight ahead: off at each bend, put back, and round it goes
        assert trial.status == "lap_complete" and trial.progress == 100.0
        assert trial.off_tracks > 0 and trial.resets == trial.off_tracks
        assert trial.penalty_ms == trial.off_tracks * 2000
        assert f"{trial.time_ms // 60000}:{trial.time_ms % 60000 / 1000:06.3f}" in printed
    assert "Off-tracks" in printed and "lap_complete" in printed

    rows = list(csv.DictReader(io.StringIO(stored(evaluation, TRACE).decode())))
    frames, size = decoded_frames(stored(evaluation, VIDEO))
    assert size == (640, 480)
    # One frame per step, that is per simulated 1/15 s; each trial's rows begin with
    # DeepRacer's prepare row, numbered by the trials done before it, with no frame of its own.
    assert frames == len(rows) - 3
    assert frames == round(sum(t.time_ms for t in trials) / STEP_MS)
    assert list(rows[0])[:3] == ["episode", "steps", "X"]
    prepares = [(r["episode"], r["steps"]) for r in rows if r["episode_status"] == "prepare"]
    assert prepares == [("0", "1.0"), ("1", "1.0"), ("2", "1.0")]
    stamps = [float(r["tstamp"]) for r in rows]
    assert all(b > a for a, b in itertools.pairwise(stamps))  # never backwards

    metrics = json.loads(stored(evaluation, METRICS))["metrics"]
    assert [m["trial"] for m in metrics] == [1, 2, 3]
    assert set(metrics[0]) == EVALUATION_KEYS
    assert metrics[0]["off_track_count"] == trials[0].off_tracks
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY
    assert_evaluation_logs_read_as_recorded(evaluation)  # in the model's logs archive
    summary = TraceSummary.objects.get(evaluation=evaluation)  # for its Analysis tab
    assert [e[0] for e in summary.episodes] == [0, 1, 2]
    assert [e[5] == 0 for e in summary.episodes] == [t.status == "lap_complete" for t in trials]


@pytest.mark.django_db
def test_a_trial_out_of_resets_ends_where_the_car_left_the_track(alice, capsys):
    model = ready_model(alice)  # straight ahead: off at the first bend
    call_command("evaluate", model.name, "--track", "pitlane-oval", "--max-resets", "0")
    evaluation = EvaluationJob.objects.get(model=model)
    assert evaluation.status == EvaluationJob.Status.COMPLETED and evaluation.max_resets == 0
    trials = list(evaluation.trial_rows.all())
    assert len(trials) == 3
    for trial in trials:
        assert trial.status == "off_track" and trial.status_display == "Off track"
        assert 0 < trial.progress < 100 and trial.off_tracks == 1 and trial.resets == 0
    metrics = json.loads(stored(evaluation, METRICS))["metrics"]
    assert {m["episode_status"] for m in metrics} == {"Off track"}
    assert evaluation.best_lap_ms is None


@pytest.mark.django_db
def test_the_evaluate_command_says_what_is_wrong(alice):
    model = ready_model(alice)
    with pytest.raises(CommandError, match="3 to 5 trials"):
        call_command("evaluate", model.name, "--trials", "7")
    with pytest.raises(CommandError, match="No model named 'nope'"):
        call_command("evaluate", "nope")
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.TRAINING)
    with pytest.raises(CommandError, match="once it is ready"):
        call_command("evaluate", model.name)
    assert not EvaluationJob.objects.exists()


@pytest.mark.django_db
def test_evaluation_settings_are_checked_as_a_whole(alice):
    model = ready_model(alice)
    with pytest.raises(configuration.Invalid) as invalid:
        services.evaluation_start(
            model=model,
            settings={
                "track": "nowhere",
                "trials": 2,
                "off_track_penalty": -1,
                "crash_penalty": "a lot",
                "checkpoint": "first",
                "race_type": "DRAG_RACE",
                "max_resets": -1,
            },
        )
    assert set(invalid.value.errors) == {
        "track",
        "trials",
        "off_track_penalty",
        "crash_penalty",
        "checkpoint",
        "race_type",
        "max_resets",
    }
    assert "0 to 10,000" in invalid.value.errors["max_resets"]
    assert not EvaluationJob.objects.exists()
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
async def test_an_evaluation_runs_on_a_worker_with_live_video_and_its_page_shows_it(
    alice, bob, celery_worker_process
):
    model = await sync_to_async(ready_model)(alice)
    evaluation = await sync_to_async(services.evaluation_start)(
        model=model, settings={"trials": 3, "continuous_laps": True, "off_track_penalty": 1}
    )
    communicator = await viewer(f"/ws/evaluations/{evaluation.pk}/", alice)
    connected, _ = await communicator.connect()
    assert connected
    assert (await communicator.receive_json_from(timeout=5))["type"] == "state"
    seen = []
    while len(seen) < 3:
        message = await communicator.receive_from(timeout=60)
        if isinstance(message, bytes):
            header, jpeg = frame_header(message)
            assert jpeg.startswith(b"\xff\xd8\xff") and header["view"] == "spectator"
            seen.append(header["step"])
            await communicator.send_json_to({"type": "ack"})
    await communicator.disconnect()  # nobody watches: the race goes on at full speed
    assert seen == sorted(seen) and seen[-1] > seen[0]

    def finished() -> bool:
        return EvaluationJob.objects.get(pk=evaluation.pk).status in ("COMPLETED", "FAILED")

    await sync_to_async(wait_for)(finished, "the evaluation to finish", timeout=180)
    await sync_to_async(check_finished_evaluation)(evaluation.pk, alice, bob)


def check_finished_evaluation(pk: int, owner, stranger) -> None:
    from django.test import Client

    evaluation = EvaluationJob.objects.select_related("model").get(pk=pk)
    assert evaluation.status == EvaluationJob.Status.COMPLETED, evaluation.failure_reason
    assert evaluation.model.status == RLModel.Status.READY
    trials = list(evaluation.trial_rows.all())
    assert len(trials) == 3 and all(t.completed for t in trials)  # three consecutive laps
    assert all(t.penalty_ms == t.off_tracks * 1000 for t in trials)
    assert default_storage.exists(evaluation.video)
    # Each lap is its own episode in the trace, as DRfC writes continuous laps, so that
    # deepracer-utils (a lap is complete where an episode's progress reaches 100) counts three.
    rows = list(csv.DictReader(io.StringIO(stored(evaluation, TRACE).decode())))
    laps = {}
    for row in rows:
        laps[row["episode"]] = max(laps.get(row["episode"], 0.0), float(row["progress"]))
    assert laps == {"0": 100.0, "1": 100.0, "2": 100.0}
    assert [r["episode_status"] for r in rows].count("prepare") == 1

    client = Client()
    client.force_login(owner)
    page = client.get(reverse("training:evaluation-detail", args=[evaluation.model.pk, pk]))
    assert page.status_code == 200
    content = page.content.decode()
    assert content.count('<tr data-number="') == 3
    assert "data-evaluation-video" in content
    video_url = reverse("training:evaluation-file", args=[evaluation.model.pk, pk, VIDEO])
    video = client.get(video_url)
    assert video.status_code == 200 and video["Content-Type"] == "video/webm"
    assert b"".join(video.streaming_content)[:4] == b"\x1a\x45\xdf\xa3"  # a Matroska/WebM file
    model_page = client.get(reverse("training:model-detail", args=[evaluation.model.pk]))
    assert "3 of 3" in model_page.content.decode()

    other = Client()
    other.force_login(stranger)
    assert other.get(page.request["PATH_INFO"]).status_code == 404
    assert other.get(video_url).status_code == 404


@pytest.mark.django_db
def test_the_evaluate_page_keeps_what_was_typed_and_says_what_to_change(client, alice):
    model = ready_model(alice)
    client.force_login(alice)
    url = reverse("training:evaluation-create", args=[model.pk])
    assert client.get(url).status_code == 200
    response = client.post(
        url,
        {
            "track": "pitlane-oval",
            "direction": "counterclockwise",
            "race_type": "TIME_TRIAL",
            "trials": "4",
            "off_track_penalty": "12",
            "crash_penalty": "5",
            "checkpoint": "last",
        },
    )
    assert response.status_code == 400
    content = response.content.decode()
    assert "Off-track penalty [s] is at most 10." in content
    assert 'value="4" selected' in content  # what was typed is kept
    assert not EvaluationJob.objects.exists()

    response = client.post(
        url,
        {
            "track": "pitlane-oval",
            "direction": "counterclockwise",
            "race_type": "TIME_TRIAL",
            "trials": "4",
            "off_track_penalty": "1.5",
            "crash_penalty": "3",
            "checkpoint": "last",
        },
    )
    evaluation = EvaluationJob.objects.get()
    assert response.status_code == 302
    assert response["Location"] == reverse(
        "training:evaluation-detail", args=[model.pk, evaluation.pk]
    )
    assert (evaluation.trials, evaluation.off_track_penalty, evaluation.checkpoint) == (
        4,
        1.5,
        "last",
    )
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.EVALUATING
    again = client.post(url, {"track": "pitlane-oval", "trials": "3"})
    assert again.status_code == 400
    assert "once it is ready" in again.content.decode()


@pytest.mark.slow
@pytest.mark.django_db
def test_an_evaluation_interrupted_by_a_dead_worker_starts_over_and_an_ended_one_never_reruns(
    alice,
):
    from jobs import evaluation as runner

    model = ready_model(alice)
    evaluation = services.evaluation_start(
        model=model, settings={"off_track_penalty": 0, "continuous_laps": True}, enqueue=False
    )
    EvaluationJob.objects.filter(pk=evaluation.pk).update(status=EvaluationJob.Status.IN_PROGRESS)
    evaluation.trial_rows.create(number=1, time_ms=1, progress=3.0, status="time_up")

    assert runner.run(evaluation.pk) is not None
    evaluation.refresh_from_db()
    assert evaluation.status == EvaluationJob.Status.COMPLETED
    trials = list(evaluation.trial_rows.all())
    assert [(t.number, t.status) for t in trials] == [(i, "lap_complete") for i in (1, 2, 3)]
    assert all(t.penalty_ms == 0 and t.resets == t.off_tracks > 0 for t in trials)

    assert runner.run(evaluation.pk) is None  # a duplicate delivery of an ended evaluation
    assert evaluation.trial_rows.count() == 3


def test_a_video_encoder_that_fails_never_holds_the_car_up(tmp_path):
    writer = _VideoWriter(tmp_path / VIDEO)

    class Broken:
        def write(self, frame):
            raise cv2.error("the encoder is gone")

        def release(self):
            pass

    writer._writer.release()
    writer._writer = Broken()  # before the first frame: the encoder thread has not touched it
    frame = np.zeros((480, 640, 3), np.uint8)
    for _ in range(3 * _VideoWriter.WAITING):  # more than may wait: none of these blocks
        writer.write(frame)
    with pytest.raises(EvaluationFailed, match="video could not be recorded"):
        writer.close()


def test_an_evaluation_whose_simulation_worker_died_is_claimed_once_and_driven_again(
    alice, tracks, monkeypatch
):
    # What every worker's heartbeat does for evaluations (console.recovery.resume_lapsed), as for
    # training jobs: the driving itself is the other tests' business.
    monkeypatch.setattr(evaluations.Race, "_drive", lambda *args: None)
    monkeypatch.setattr(evaluations.EvaluationCar, "_save", lambda *args: None)
    model = trained_model(alice, "lapsing")
    started = services.evaluation_start(model=model, settings={"trials": 3}, enqueue=False)
    dead = "simulation-1:4242:cafe"
    EvaluationJob.objects.filter(pk=started.pk).update(
        status=EvaluationJob.Status.IN_PROGRESS,
        lease_owner=dead,
        lease_expires=timezone.now() + timedelta(seconds=30),
    )
    assert evaluations.run(started.pk) is None  # a second delivery leaves a live run alone
    assert leases.lapsed_evaluations() == []
    assert EvaluationJob.objects.get(pk=started.pk).lease_owner == dead

    past = timezone.now() - timedelta(seconds=1)
    EvaluationJob.objects.filter(pk=started.pk).update(lease_expires=past)  # its machine died
    assert [e.pk for e in leases.lapsed_evaluations()] == [started.pk]
    assert leases.lapsed_evaluations() == []  # claimed once: one new run is sent for
    claimed = EvaluationJob.objects.get(pk=started.pk)
    assert claimed.message == leases.EVALUATION_LAPSED and claimed.lease_owner == leases.RESUMING
    answers = signals.evaluation_lapsed.send(EvaluationJob, evaluation=claimed)
    assert not any(sent for _, sent in answers)  # no race's: its own task is sent

    assert evaluations.run(started.pk) is not None  # driven again, from the start
    done = EvaluationJob.objects.get(pk=started.pk)
    assert done.status == EvaluationJob.Status.COMPLETED and done.lease_owner == ""
    # The dead run, were it alive, stops at its next renewal rather than write.
    stale = evaluations.EvaluationCar(EvaluationJob.objects.get(pk=started.pk))
    stale.evaluation.lease_owner, stale.renewals = dead, Every(0.0)  # renewed at once
    with pytest.raises(leases.LeaseLost):
        stale._renew()


def test_a_run_overtaken_while_it_saves_leaves_the_evaluation_and_its_model_to_the_new_run(
    alice, tracks, monkeypatch
):
    # A slow upload outlived the lease; the heartbeat sent the evaluation to another run, which
    # drives it now. The old run's end must not free the model nor tell the racer it is done.
    taker = "simulation-2:77:beef"

    def overtaken(self, video_path):
        EvaluationJob.objects.filter(pk=self.evaluation.pk).update(lease_owner=taker)

    monkeypatch.setattr(evaluations.Race, "_drive", lambda *args: None)
    monkeypatch.setattr(evaluations.EvaluationCar, "_save", overtaken)
    model = trained_model(alice, "overtaken")
    started = services.evaluation_start(model=model, settings={"trials": 3}, enqueue=False)
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.EVALUATING
    evaluations.run(started.pk)
    after = EvaluationJob.objects.get(pk=started.pk)
    assert after.status == EvaluationJob.Status.IN_PROGRESS and after.lease_owner == taker
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.EVALUATING
    assert not alice.notifications.exists()


@pytest.mark.slow
@pytest.mark.django_db
def test_three_trials_differ_and_the_evaluate_command_replays_them_by_their_seed(alice, capsys):
    model = ready_model(alice)  # straight ahead, off at the first bend: short trials
    call_command("evaluate", model.name, "--trials", "3", "--max-resets", "0")
    first = EvaluationJob.objects.get(model=model)
    assert f"seed {first.seed}" in capsys.readouterr().out
    paths = trial_paths(first)
    assert len(paths) == 3 and paths[0] != paths[1] != paths[2] != paths[0]
    seeds = [trial.seed for trial in first.trial_rows.all()]
    assert len(set(seeds)) == 3 and seeds == [first.trial_seed(n) for n in range(3)]

    call_command("evaluate", model.name, "--max-resets", "0", "--seed", str(first.seed))
    again = EvaluationJob.objects.exclude(pk=first.pk).get(model=model)
    assert again.seed == first.seed
    assert trial_paths(again) == paths
    times = [[t.time_ms for t in e.trial_rows.all()] for e in (first, again)]
    assert times[0] == times[1]


@pytest.mark.django_db
def test_an_evaluation_made_before_seeds_drives_its_trials_without_noise(alice):
    model = ready_model(alice)
    evaluation = services.evaluation_start(model=model, settings={"max_resets": 0}, enqueue=False)
    EvaluationJob.objects.filter(pk=evaluation.pk).update(seed=None)
    evaluations.run(evaluation.pk)
    evaluation.refresh_from_db()
    paths = trial_paths(evaluation)
    assert paths[0] == paths[1] == paths[2]
    assert [trial.seed for trial in evaluation.trial_rows.all()] == [None] * 3


@pytest.mark.django_db
def test_the_evaluation_page_shows_its_seed(client, alice):
    model = ready_model(alice)
    evaluation = services.evaluation_start(
        model=model, settings={"trials": 3}, seed=1234, enqueue=False
    )
    client.force_login(alice)
    page = client.get(reverse("training:evaluation-detail", args=[model.pk, evaluation.pk]))
    assert "seed 1234" in page.content.decode()


@pytest.mark.django_db
def test_a_seed_out_of_range_is_refused_in_words(alice):
    with pytest.raises(configuration.Invalid) as refused:
        services.evaluation_start(model=ready_model(alice), settings={}, seed=-1, enqueue=False)
    assert refused.value.errors == {"seed": "A seed is a whole number from 0 to 2147483647."}
