"""A model's history survives a round trip through its virtual archive: the same iteration figures
to the last bit, the same best-checkpoint label, and its simulation traces for the Analysis tab.
An archive from elsewhere, without them, says on the model's page what was rebuilt or is missing."""

from __future__ import annotations

import io
import json
import shutil
import tarfile

import pytest
from django.conf import settings
from django.db import connection
from django.db.models import Max
from django.urls import reverse

from analysis.records import Source
from archives import exports, history, imports
from simulator.trace import to_csv
from tests.helpers.analysis import HAND_WRITTEN
from tests.helpers.archives import tar_gz, trainer_metrics, virtual_archive
from tests.helpers.models import ready_model
from training import artifacts, selectors
from training.models import EvaluationJob, Iteration, RLModel, TrainingJob

pytestmark = pytest.mark.django_db

FIGURES = (
    "number",
    "reward",
    "completion",
    "evaluation_completion",
    "best_lap_time",
    "episodes",
    "steps",
    "wall_seconds",
    "time_split",
    "evaluation_seconds",
    "training_points",
    "evaluation_points",
)


def trained_three_iterations(owner) -> RLModel:
    """A model whose page shows figures DeepRacer's metrics would round (11.9 reward, 8.0%
    completion), whose best checkpoint is iteration 2 and last iteration 3, with a simulation
    trace for each iteration."""
    model = ready_model(owner)
    job = model.jobs.get()
    weights = artifacts.read(job.best_checkpoint)
    best = artifacts.save(model, artifacts.checkpoint(2), weights)
    last = artifacts.save(model, artifacts.checkpoint(3), weights)
    for number in (1, 2, 3):
        Iteration.objects.create(
            job=job,
            number=number,
            reward=11.9 + number / 3,
            completion=8.0 / number,
            evaluation_completion=[None, 41.66666666666667, 12.5][number - 1],
            best_lap_time=None if number < 3 else 9.933333333333334,
            episodes=3,
            steps=101,
            wall_seconds=0.1 + 0.2 * number,
            time_split={"rollout": 0.30000000000000004},
            evaluation_seconds=1 / 7,
            training_points=[[11.9049, 7.51], [0.1 + 0.2, 8.0]],
            evaluation_points=[41.66666666666667, 33.3],
        )
        artifacts.save(model, artifacts.training_trace(number), to_csv(HAND_WRITTEN))
    artifacts.save(model, artifacts.TRAINING_METRICS, json.dumps(trainer_metrics(3)))
    TrainingJob.objects.filter(pk=job.pk).update(
        iterations=3, best_checkpoint=best, last_checkpoint=last, training_seconds=42.5
    )
    return model


def imported(owner, archive: bytes) -> RLModel:
    """The model imported from ``archive``. Tests roll back, so primary keys come again, and
    share one media folder: what an earlier test left under the new model's prefix goes first
    (as tests/analysis clears its models')."""
    after = RLModel.objects.aggregate(pk=Max("pk"))["pk"] or 0
    for pk in range(after + 1, after + 3):
        shutil.rmtree(settings.MEDIA_ROOT / "models" / str(pk), ignore_errors=True)
    model = imports.import_model(owner=owner, archive=io.BytesIO(archive)).model
    model.refresh_from_db()
    return model


def figures(model: RLModel) -> list[tuple]:
    rows = model.jobs.get().iteration_rows.order_by("number")
    return [tuple(getattr(row, name) for name in FIGURES) for row in rows]


def labels(model: RLModel) -> list[str]:
    return [choice.label for choice in selectors.model_checkpoint_choices(model=model)]


@pytest.mark.slow
def test_a_virtual_model_comes_back_with_the_same_figures_checkpoints_and_traces(
    alice, bob, tracks, client
):
    original = trained_three_iterations(alice)
    model = imported(bob, virtual_archive(original))
    assert figures(model) == figures(original)  # every float to the last bit
    assert (
        labels(model)
        == labels(original)
        == [
            "Best: iteration 2, 42% evaluation completion",
            "Last: iteration 3, 12% evaluation completion",
        ]
    )
    job = model.jobs.get()
    assert (job.iterations, job.episodes, job.steps, job.training_seconds) == (3, 9, 303, 42.5)
    assert not any("rebuilt" in note or "traces" in note for note in model.import_notes)
    client.force_login(bob)
    page = client.get(reverse("analysis:model", args=[model.pk]))
    assert [row["iteration"] for row in page.context["overview"]["iterations"]] == [1, 2, 3]
    assert page.context["unreadable"] == []
    episodes = client.get(reverse("analysis:model", args=[model.pk]) + "data.json").json()
    assert [e[:2] for e in episodes["episodes"]][:2] == [[1, 0], [1, 1]]
    assert (
        "data-import-notes"
        not in client.get(reverse("training:model-detail", args=[model.pk])).text
    )


def members_of(archive: bytes) -> dict[str, bytes]:
    with tarfile.open(fileobj=io.BytesIO(archive), mode="r:gz") as tar:
        return {member.name: tar.extractfile(member).read() for member in tar}


@pytest.mark.slow
def test_the_archive_keeps_deepracers_files_as_they_are_and_its_traces_where_deepracer_does(
    alice, tracks
):
    members = members_of(virtual_archive(trained_three_iterations(alice)))
    assert json.loads(members[artifacts.TRAINING_METRICS]) == trainer_metrics(3)
    assert {f"training-simtrace/{n}-iteration.csv" for n in range(3)} <= set(members)
    assert json.loads(members[history.EXACT])["checkpoints"] == {"best": 2, "last": 3}


@pytest.mark.slow
def test_an_archive_from_elsewhere_says_on_the_models_page_what_was_rebuilt_and_is_missing(
    alice, bob, tracks, client
):
    members = members_of(virtual_archive(trained_three_iterations(alice)))
    bare = {
        name: data
        for name, data in members.items()
        if name != history.EXACT and not name.startswith("training-simtrace/")
    }
    model = imported(bob, tar_gz(bare))
    rebuilt = figures(model)
    assert len(rebuilt) == 3 and rebuilt != figures(RLModel.objects.get(owner=alice))
    assert labels(model) == ["Best", "Last"]  # not which iteration
    client.force_login(bob)
    page = client.get(reverse("training:model-detail", args=[model.pk])).text
    notes = page[page.index("data-import-notes") :]
    assert "Training figures rebuilt from DeepRacer&#x27;s metrics, which round them" in notes
    assert "The archive has no simulation traces (training-simtrace): the Analysis tab" in notes
    assert (
        b"<strong>Nothing recorded yet.</strong>"
        in client.get(reverse("analysis:model", args=[model.pk])).content
    )


@pytest.mark.slow
def test_a_damaged_record_falls_back_to_the_metrics_and_traces_past_the_limit_stay_behind(
    alice, bob, tracks, monkeypatch
):
    members = members_of(virtual_archive(trained_three_iterations(alice)))
    monkeypatch.setattr(exports, "TRACES_LIMIT", 2 * len(to_csv(HAND_WRITTEN).encode()))
    model = imported(bob, tar_gz({**members, history.EXACT: b"{"}))
    said = " ".join(model.import_notes)
    assert f"The archive's {history.EXACT} could not be read (it is not JSON)." in said
    assert "Training figures rebuilt from DeepRacer's metrics" in said
    assert model.jobs.get().iterations == 3
    assert "Simulation traces came for 2 of the archive's 3 iterations" in said
    assert Source.of_job(model.jobs.get()).iterations() == [2, 3]  # the newest come first


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_the_archive_fills_its_trace_budget_with_the_newest_training_traces_first(
    alice, tracks, monkeypatch
):
    model = trained_three_iterations(alice)
    evaluation = EvaluationJob.objects.create(model=model, track=model.track, status="COMPLETED")
    trace = artifacts.evaluation_prefix(evaluation) + artifacts.EVALUATION_TRACE
    artifacts.save(model, trace, to_csv(HAND_WRITTEN))
    monkeypatch.setattr(exports, "TRACES_LIMIT", 2 * len(to_csv(HAND_WRITTEN).encode()))
    assert [trace.relative for trace in exports.chosen_traces(model)] == [
        "training-simtrace/2-iteration.csv",
        "training-simtrace/1-iteration.csv",
    ]  # an import keeps the training's; the evaluation's only in the room left
    monkeypatch.setattr(exports, "TRACES_LIMIT", 4 * len(to_csv(HAND_WRITTEN).encode()))
    assert exports.chosen_traces(model)[-1].relative.endswith("evaluation-simtrace/0-iteration.csv")


@pytest.mark.slow
def test_an_archive_already_built_is_found_without_reading_its_traces(alice, tracks, monkeypatch):
    model = trained_three_iterations(alice)
    built = exports.virtual(model)
    read = []
    original = artifacts.read
    monkeypatch.setattr(artifacts, "read", lambda name: read.append(name) or original(name))
    assert exports.virtual(model) == built
    assert read and not [name for name in read if "simtrace" in name]


@pytest.mark.slow
def test_traces_over_the_limit_are_the_newest_iterations_whatever_the_archives_order(
    alice, bob, tracks, monkeypatch
):
    members = members_of(virtual_archive(trained_three_iterations(alice)))
    traces = sorted(name for name in members if name.startswith("training-simtrace/"))
    oldest_first = {name: data for name, data in members.items() if name not in traces}
    oldest_first.update({name: members[name] for name in traces})  # 0-, 1-, 2-iteration.csv
    monkeypatch.setattr(exports, "TRACES_LIMIT", 2 * len(to_csv(HAND_WRITTEN).encode()))
    model = imported(bob, tar_gz(oldest_first))
    assert Source.of_job(model.jobs.get()).iterations() == [2, 3]


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_the_traces_are_written_after_the_import_commits_the_model(alice, bob, tracks, monkeypatch):
    archive = virtual_archive(trained_three_iterations(alice))
    outside, depths = len(connection.atomic_blocks), []
    save = artifacts.save

    def recording(model, relative, data):
        if "simtrace" in relative or relative == artifacts.TRAINING_METRICS:
            depths.append(len(connection.atomic_blocks))
        return save(model, relative, data)

    monkeypatch.setattr(artifacts, "save", recording)
    imported(bob, archive)
    assert depths == [outside] * 4  # the metrics and three traces, the quota row unlocked


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_traces_that_storage_fails_to_keep_are_a_note_and_the_model_stays(
    alice, bob, tracks, monkeypatch
):
    archive = virtual_archive(trained_three_iterations(alice))
    save = artifacts.save

    def failing(model, relative, data):
        if relative == artifacts.training_trace(2):
            raise OSError("the bucket is gone")
        return save(model, relative, data)

    monkeypatch.setattr(artifacts, "save", failing)
    model = imported(bob, archive)
    assert model.status == RLModel.Status.READY and model.jobs.get().iterations == 3
    assert (
        "Storage failed while the archive's training metrics and simulation traces were kept: "
        "1 of its 3 traces were" in " ".join(model.import_notes)
    )
    assert Source.of_job(model.jobs.get()).iterations() == [1]


@pytest.mark.parametrize(
    ("document", "why"),
    [
        ({"format": 2, "iterations": []}, "not a format this console reads"),
        ({"format": 1, "iterations": []}, "holds no iteration"),
        ({"format": 1, "iterations": [{"number": 2}]}, "iteration 1 is missing or out of order"),
        ({"format": 1, "iterations": [{"number": 1, "reward": "NaN"}]}, "no finite reward"),
        ({"format": 1, "iterations": [{"number": 1, "reward": 1, "completion": 2,
                                       "wall_seconds": 3, "episodes": -1}]}, "whole number"),
    ],
)  # fmt: skip
def test_a_record_with_anything_amiss_is_unreadable_and_says_what(document, why):
    with pytest.raises(history.Unreadable, match=why):
        history.exact_read(json.dumps(document).encode())
