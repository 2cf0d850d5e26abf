"""The analysis reads recorded traces as the community's notebooks do: a trace written by hand is
summarised as counted by hand, a driven job's as deepracer-utils reads it, and the pages give a
racer their own model's driving and nobody else's."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from deepracer.logs import AnalysisUtils, DeepRacerLog
from django.urls import reverse

import simulator
from analysis import records, selectors, summaries, traces
from analysis.models import TraceSummary
from simulator import tracks as sim_tracks
from simulator.controller import CentreLineDriver
from simulator.params import replayed
from simulator.trace import to_csv
from tests.helpers.analysis import HAND_WRITTEN, recorded_by_hand, untrained
from tests.helpers.training_logs import EPISODES, extracted, new_model, train_on_paper
from training import artifacts
from training.models import EvaluationJob, TrainingJob

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]

STEP = 1 / 15  # [s]


def test_a_hand_written_trace_is_summarised_as_counted_by_hand(alice):
    job = recorded_by_hand(alice)
    summary = TraceSummary.objects.get(job=job, iteration=1)  # made as it was recorded
    assert summary.version == summaries.VERSION
    # [number, start waypoint, steps, progress, seconds, outcome, total reward]
    assert summary.episodes == [[0, 0, 4, 100.0, 0.2, 0, 6.0], [1, 5, 3, 3.5, 0.133, 1, 0.501]]
    assert summary.marks == [[1.5, 2.5, 1, 1]]  # where it left the track: its second episode
    assert summary.steps == 5  # the prepare rows are not driven steps
    tables = summaries.action_tables(bytes(summary.actions))
    assert not tables[2:].any()  # nothing crashed, nothing else
    lap, off = (_split(table) for table in tables[:2])
    # Sections: waypoints 0-10 are the first tenth, 55 the sixth, 109 the last.
    assert _cells(lap["actions"]) == {(0, 0): 1, (5, 2): 1, (9, 2): 1}
    assert _cells(off["actions"]) == {(0, 1): 2}
    # Steering bins of 5° from -30°; speed bins of 0.25 m/s from 0.
    assert _cells(lap["steer"]) == {(0, 0): 1, (5, 6): 1, (9, 6): 1}
    assert _cells(off["steer"]) == {(0, 9): 2}
    assert _cells(lap["speed"]) == {(0, 4): 1, (5, 8): 1, (9, 8): 1}
    assert _cells(off["speed"]) == {(0, 2): 2}
    points = summaries.points_array(bytes(summary.points))
    assert points.shape == (len(summaries.POINT_COLUMNS), 5)
    column = dict(zip(summaries.POINT_COLUMNS, points, strict=True))
    assert column["reward"].tolist() == pytest.approx([1.0, 2.0, 3.0, 0.5, 0.001])
    assert column["outcome"].tolist() == [0, 0, 0, 1, 1]
    assert column["row"].tolist() == [1, 2, 3, 5, 6]
    assert summaries.iteration_figures(summary.episodes) == {
        "episodes": 2,
        "reward": pytest.approx(3.2505),
        "progress": pytest.approx(51.75),
        "completion": 50.0,
        "best_lap": 0.2,
        "median_lap": 0.2,
    }


def _split(table: np.ndarray) -> dict[str, np.ndarray]:
    """One outcome's counts: 13 steering bins, 16 speed bins, then the model's actions."""
    return {"steer": table[:, :13], "speed": table[:, 13:29], "actions": table[:, 29:]}


def _cells(table) -> dict[tuple[int, int], int]:
    return {(i, j): count for i, line in enumerate(table) for j, count in enumerate(line) if count}


@pytest.mark.slow
def test_a_driven_job_is_summarised_as_deepracer_utils_reads_it(alice, tracks):
    model = new_model(alice, "driven")
    train_on_paper(model)  # two iterations of 4 episodes: laps and straight off the track
    source = records.Source.of_job(model.jobs.get())
    assert source.ensure() == []  # recorded before any summary: made when first asked for
    rows = {s.iteration: s for s in source.summaries()}
    assert sorted(rows) == [1, 2]
    with tempfile.TemporaryDirectory() as directory:
        log = DeepRacerLog(str(extracted(model, Path(directory))))
        log.load_training_trace()
        agg = AnalysisUtils.simulation_agg(log.dataframe(), secondgroup="unique_episode")
    for iteration, summary in rows.items():
        theirs = agg[agg["iteration"] == iteration - 1].sort_values("unique_episode")
        assert len(summary.episodes) == len(theirs) == EPISODES
        for ours, (_, their) in zip(summary.episodes, theirs.iterrows(), strict=True):
            _, start, steps, progress, seconds, outcome, reward = ours
            assert steps == their["steps"]
            assert start == their["start_at"]
            assert progress == pytest.approx(their["progress"], abs=0.01)
            assert seconds == pytest.approx(their["time"], abs=1e-3)
            assert reward == pytest.approx(their["reward"], abs=1e-3 * steps)
            assert (outcome == 0) == bool(their["complete"])
    laps = [e for s in rows.values() for e in s.episodes if e[5] == 0]
    assert laps and all(e[4] == pytest.approx((e[2] - 1) * STEP, abs=1e-3) for e in laps)


def test_the_params_replayed_from_a_trace_are_those_the_car_was_given(tracks):
    env = gymnasium.make(simulator.ENV_ID, track="pitlane-oval")
    _, info = env.reset(seed=0)
    driver = CentreLineDriver(env.unwrapped)
    given, rows = [], []
    while True:
        _, _, terminated, truncated, info = env.step(driver.act())
        given.append(info["params"])
        rows.append(info["trace"])
        if terminated or truncated or len(rows) == 60:
            break
    env.close()
    steps = traces.read(to_csv(rows))  # through the CSV, rounded as it is stored
    recorded = steps.recorded(slice(None))
    track = sim_tracks.driven("pitlane-oval", "counterclockwise")
    for theirs, ours in zip(given, replayed(track, recorded), strict=True):
        assert set(ours) == set(theirs) - {"waypoints"}
        for name in (
            "x",
            "y",
            "heading",
            "distance_from_center",
            "track_width",
            "progress",
            "speed",
            "steering_angle",
            "projection_distance",
            "sim_time",
        ):
            assert ours[name] == pytest.approx(theirs[name], abs=2e-3), name
        for name in (
            "steps",
            "closest_waypoints",
            "all_wheels_on_track",
            "is_offtrack",
            "is_crashed",
            "is_reversed",
            "track_length",
        ):
            assert ours[name] == theirs[name], name
        if theirs["distance_from_center"] > 1e-3:  # on the line, the stored digits pick a side
            assert ours["is_left_of_center"] == theirs["is_left_of_center"]


def test_the_pages_pick_iterations_and_outcomes_and_show_one_episode(alice, client):
    job = recorded_by_hand(alice)
    model = job.model
    client.force_login(alice)
    base = reverse("analysis:model", args=[model.pk])
    page = client.get(base)
    assert page.status_code == 200
    overview = page.context["overview"]
    assert [row["iteration"] for row in overview["iterations"]] == [1]
    assert len(overview["track"]["centre"]) == 111

    everything = client.get(f"{base}data.json").json()
    assert [e[:2] for e in everything["episodes"]] == [[1, 0], [1, 1]]
    assert everything["fastest"] == [1, 0]
    assert everything["marks"] == [[1.5, 2.5, 1, 1, 1]]
    laps = client.get(f"{base}data.json?outcomes=lap_complete").json()
    assert [e[:2] for e in laps["episodes"]] == [[1, 0]] and laps["marks"] == []
    assert laps["actions"]["speed"][5][8] == 1 and sum(map(sum, laps["actions"]["speed"])) == 3

    data = client.get(f"{base}points.bin?outcomes=off_track").content
    columns = len(summaries.POINT_COLUMNS) + 1  # and the iteration
    points = np.frombuffer(data, dtype="<f4").reshape(columns, -1)
    assert points.shape[1] == 2 and points[-1].tolist() == [1, 1]

    shown = client.get(f"{base}episode.json?iteration=1&episode=1").json()
    assert shown["outcome"] == "off_track" and len(shown["path"]) == 3
    assert shown["params"][2]["is_offtrack"] is True
    assert shown["params"][1]["distance_from_center"] == pytest.approx(0.0, abs=0.01)
    missing = client.get(f"{base}episode.json?iteration=1&episode=7")
    assert missing.status_code == 404 and "has no episode 7" in missing.json()["error"]
    assert client.get(f"{base}episode.json?iteration=one").status_code == 400
    for unknown in ("4", "-1", "9" * 300):  # never read from the storage by such a name
        lost = client.get(f"{base}episode.json?iteration={unknown}&episode=0")
        assert (
            lost.status_code == 404 and lost.json()["error"] == "That iteration was not recorded."
        )
    # Wrong choices fall back to everything, never to an error.
    assert client.get(f"{base}data.json?first=x&last=-4&outcomes=nope").json()["episodes"]
    alone = client.get(f"{base}points.bin").content
    for rescoring in ("²", "9" * 40, "-1"):  # no re-scoring's id: the points alone
        assert client.get(f"{base}points.bin?rescoring={rescoring}").content == alone


def test_only_the_owner_sees_a_models_analysis(alice, bob, client):
    job = recorded_by_hand(alice)
    client.force_login(bob)
    base = reverse("analysis:model", args=[job.model.pk])
    for url in (
        base,
        f"{base}data.json",
        f"{base}points.bin",
        f"{base}episode.json?iteration=1&episode=0",
    ):
        assert client.get(url).status_code == 404


def test_a_model_with_nothing_recorded_says_so(alice, client):
    model = untrained(alice, "quiet")
    client.force_login(alice)
    page = client.get(reverse("analysis:model", args=[model.pk]))
    assert page.status_code == 200
    assert b"Nothing recorded yet" in page.content


def test_a_broken_trace_is_left_out_with_a_word(alice, client):
    job = recorded_by_hand(alice)
    artifacts.save(job.model, artifacts.training_trace(2), "episode,steps\n1,2\n")
    client.force_login(alice)
    page = client.get(reverse("analysis:model", args=[job.model.pk]))
    assert page.context["unreadable"] == [2]
    assert b"could not be read" in page.content
    with pytest.raises(traces.Unreadable, match="no column"):
        traces.read(b"episode,steps\n1,2\n")
    with pytest.raises(traces.Unreadable, match="not a number"):
        traces.read(to_csv(HAND_WRITTEN).replace("10.067", "soon"))


def test_a_job_still_training_leaves_its_newest_trace_to_the_trainer(alice):
    # A page view may come while the trainer writes its newest trace: that one is not read, so a
    # half-written trace never becomes a summary; once the job has ended, every one is read.
    job = recorded_by_hand(alice)
    TraceSummary.objects.filter(job=job).delete()
    half = to_csv(HAND_WRITTEN)
    artifacts.save(job.model, artifacts.training_trace(2), half[: len(half) * 2 // 3])
    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.IN_PROGRESS)
    training = records.Source.of_job(TrainingJob.objects.get(pk=job.pk))
    assert training.ensure() == []
    assert list(training.summaries().values_list("iteration", flat=True)) == [1]
    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED)
    artifacts.save(job.model, artifacts.training_trace(2), half)  # whole now
    ended = records.Source.of_job(TrainingJob.objects.get(pk=job.pk))
    assert ended.ensure() == []
    assert sorted(ended.summaries().values_list("iteration", flat=True)) == [1, 2]
    assert ended.summaries().get(iteration=2).steps == 5


def test_the_overview_is_json_for_the_page(alice):
    job = recorded_by_hand(alice)
    overview = selectors.overview(records.Source.of_job(job))
    assert json.loads(json.dumps(overview)) == overview
    assert overview["actions"][0].startswith("0: ")


def test_an_evaluations_trials_have_their_analysis_tab(alice, client):
    model = untrained(alice, "evaluated")
    evaluation = EvaluationJob.objects.create(
        model=model, track=model.track, trials=2, status=EvaluationJob.Status.COMPLETED
    )
    document = to_csv(HAND_WRITTEN)  # its two episodes stand for two trials
    artifacts.save(
        model, artifacts.evaluation_prefix(evaluation) + artifacts.EVALUATION_TRACE, document
    )
    client.force_login(alice)
    detail = client.get(reverse("training:evaluation-detail", args=[model.pk, evaluation.pk]))
    base = reverse("analysis:evaluation", args=[model.pk, evaluation.pk])
    assert base.encode() in detail.content  # the tab beside the results
    page = client.get(base)
    assert page.status_code == 200 and page.context["evaluation"] == evaluation
    assert TraceSummary.objects.get(evaluation=evaluation).steps == 5  # made when first asked
    picked = client.get(f"{base}data.json").json()
    assert [e[:2] for e in picked["episodes"]] == [[0, 0], [0, 1]]
    assert client.get(f"{base}episode.json?iteration=0&episode=1").json()["outcome"] == "off_track"
    stranger = reverse("analysis:evaluation", args=[model.pk + 1000, evaluation.pk])
    assert client.get(stranger).status_code == 404
