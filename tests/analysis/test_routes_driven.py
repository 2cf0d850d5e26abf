"""A model's driving is replayed on the route it drove. DeepRacer for Cloud names a bare
WORLD_NAME (reInvent2019_track), and simapp drives that file, reInvent2019_track.npy (154
waypoints: bundle/markov/track_geom/track_data.py:194-198, 01f5f01), where the console drives
reInvent2019_track_ccw.npy (79 waypoints, metres away): the Analysis map, its episodes' params
and re-scoring read the imported model's route, and an evaluation on another track that
track's."""

from __future__ import annotations

import importlib
import io
import json
import shutil

import gymnasium
import numpy as np
import pytest
import yaml
from django.apps import apps as django_apps
from django.conf import settings as django_settings
from django.urls import reverse

import simulator
from analysis import rescoring, services, summaries
from analysis.models import Rescoring, TraceSummary
from analysis.records import Source
from archives import imports
from simulator import tracks as sim_tracks
from simulator.controller import CentreLineDriver
from simulator.trace import to_csv
from tests.helpers.analysis import recorded_by_hand
from tests.helpers.archives import (
    DEEPRACER_METADATA,
    DEEPRACER_PARAMS,
    deepracer_export,
    tar_gz,
)
from training import artifacts
from training.models import EvaluationJob, RLModel, Track, TrainingJob

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]

WORLD = "reInvent2019_track"  # DeepRacer for Cloud's default (template-worker.env:1)
STEPS = 45  # driven in the recorded episode, 3 s
# A continuous action space, which the scripted driver follows the centre line with.
CONTINUOUS = {
    **DEEPRACER_METADATA,
    "action_space_type": "continuous",
    "action_space": {
        "steering_angle": {"low": -30.0, "high": 30.0},
        "speed": {"low": 0.5, "high": 1.5},
    },
}


def imported_from_drfc(owner) -> RLModel:
    """A DeepRacer for Cloud model folder on the bare WORLD_NAME, imported: it trains on
    simapp's reInvent2019_track.npy."""
    archive = tar_gz(
        deepracer_export(
            **{
                "model_metadata.json": json.dumps(CONTINUOUS).encode(),
                "training_params.yaml": yaml.safe_dump(
                    {**DEEPRACER_PARAMS, "WORLD_NAME": WORLD}
                ).encode(),
            }
        )
    )
    model = imports.import_model(owner=owner, archive=io.BytesIO(archive)).model
    model.refresh_from_db()
    assert (model.track.name, model.world_name) == (WORLD, WORLD)
    # Tests roll back and primary keys come again: nothing an earlier test left under its prefix.
    shutil.rmtree(django_settings.MEDIA_ROOT / "models" / str(model.pk), ignore_errors=True)
    return model


def driven_on_simapps_route(model: RLModel) -> list:
    """An episode driven on reInvent2019_track.npy as simapp drives it, scored by the model's
    own reward function: its trace rows, the prepare row first."""
    namespace: dict = {}
    exec(model.reward_function, namespace)  # noqa: S102 (the archive's: our first example)
    env = gymnasium.make(
        simulator.ENV_ID,
        track=WORLD,
        route=WORLD,
        action_space=model.action_space,
        reward_fn=namespace["reward_function"],
    )
    _, info = env.reset(seed=0)
    rows = [info["trace"]]
    driver = CentreLineDriver(env.unwrapped)
    for _ in range(STEPS):
        _, _, terminated, truncated, info = env.step(driver.act())
        rows.append(info["trace"])
        if terminated or truncated:
            break
    env.close()
    return rows


def recorded(model: RLModel) -> tuple[TrainingJob, list]:
    """``model``'s training job, ended, with an episode driven on simapp's route as its first
    iteration's trace."""
    rows = driven_on_simapps_route(model)
    job = model.jobs.get()
    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED, iterations=1)
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.READY)
    artifacts.save(model, artifacts.training_trace(1), to_csv(rows))
    job.refresh_from_db()
    return job, rows


def as_track(shown: dict) -> sim_tracks.Track:
    """The track the Analysis map draws (its centre line and borders), loaded as a track."""
    route = np.column_stack([shown["centre"], shown["inner"], shown["outer"]])
    return sim_tracks.load({"name": "shown", "route": route})


@pytest.mark.slow
def test_a_drfc_import_on_a_bare_world_name_is_analysed_on_the_route_it_drove(alice, client):
    model = imported_from_drfc(alice)
    job, rows = recorded(model)
    drove = sim_tracks.load(WORLD).on_route(WORLD)  # simapp's file, 154 waypoints
    client.force_login(alice)
    base = reverse("analysis:model", args=[model.pk])

    # The map draws simapp's route, and every step of the car lies on it, not in the grass.
    page = client.get(base)
    shown = page.context["overview"]["track"]
    assert len(shown["centre"]) == len(drove.centre) == 154
    assert np.allclose(shown["centre"], drove.centre, atol=1e-3)
    data = client.get(f"{base}points.bin").content
    points = np.frombuffer(data, dtype="<f4").reshape(len(summaries.POINT_COLUMNS) + 1, -1)
    xy = points[:2].T.astype(np.float64)
    assert len(xy) == len(rows) - 1  # the steps driven, not the prepare row
    on_map = as_track(shown).project_points(xy)
    assert (on_map.offset < on_map.half_width).all(), on_map.offset.max()
    assert on_map.offset.max() < 0.15  # the driver holds the centre line: within 15 cm

    # An episode's params, replayed from the trace, put the car on the track near its centre.
    episode = client.get(f"{base}episode.json?iteration=1&episode=0").json()
    params = episode["params"]
    assert len(params) == len(rows) and all(p["all_wheels_on_track"] for p in params)
    assert all(p["distance_from_center"] < p["track_width"] / 2 for p in params)
    assert max(p["distance_from_center"] for p in params) < 0.15
    assert {len(p["closest_waypoints"]) for p in params} == {2}
    assert max(max(p["closest_waypoints"]) for p in params) < 154

    # Re-scored with its own reward function: the rewards it was given when it drove.
    asked = services.rescoring_create(
        source=Source.of_job(job),
        owner=alice,
        reward_function=model.reward_function,
        first=None,
        last=None,
    )
    rescoring.run(asked.pk)
    asked.refresh_from_db()
    assert asked.status == asked.Status.DONE, asked.failure
    given = sum(row.reward for row in rows[1:])
    assert given == pytest.approx(len(rows) - 1)  # 1.0 a step: on the centre line
    ((number, total),) = asked.episodes["1"]
    assert (number, total) == (0, pytest.approx(given, abs=1e-3))
    new = np.frombuffer(bytes(asked.points), dtype=np.float32)
    assert new.tolist() == pytest.approx([row.reward for row in rows[1:]])


def test_an_evaluation_is_replayed_on_its_own_track_and_on_the_models_route_on_the_models(
    alice,
):
    model = imported_from_drfc(alice)
    elsewhere = EvaluationJob.objects.create(
        model=model, track=Track.objects.get(name="pitlane-oval"), direction="clockwise"
    )
    at_home = EvaluationJob.objects.create(
        model=model, track=model.track, direction="counterclockwise"
    )
    oval = Source.of_evaluation(elsewhere).track
    assert (oval.name, oval.direction) == ("pitlane-oval", "clockwise")
    assert np.allclose(oval.centre, sim_tracks.load("pitlane-oval").centre[::-1])
    home = Source.of_evaluation(at_home).track
    assert (home.world_name, len(home.centre)) == (WORLD, 154)
    # The console's route for the direction where the model drives none of its own.
    consoles = sim_tracks.load(WORLD).with_direction("counterclockwise")
    assert (consoles.world_name, len(consoles.centre)) == ("reInvent2019_track_ccw", 79)
    assert Source.of_job(model.jobs.get()).track.world_name == WORLD
    # What is replayed is what was driven: the environment of each (its video's map, too).
    for evaluation in (elsewhere, at_home):
        env = gymnasium.make(simulator.ENV_ID, **evaluation.environment_settings()).unwrapped
        assert np.array_equal(env.track.centre, Source.of_evaluation(evaluation).track.centre)
        env.close()
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings()).unwrapped
    assert np.array_equal(env.track.centre, model.driven_track().centre)
    env.close()


def test_summaries_made_on_the_consoles_route_are_made_again_on_the_models(alice):
    model = imported_from_drfc(alice)
    job, _ = recorded(model)
    mine = recorded_by_hand(alice).model  # on the console's route: summarised as recorded
    Source.of_job(job).ensure()
    done = Rescoring.objects.create(
        owner=alice, job=job, reward_function="", status=Rescoring.Status.DONE, points=b"1234"
    )
    migration = importlib.import_module("analysis.migrations.0003_routes_driven")
    migration.forget_what_was_made_on_the_consoles_route(django_apps, None)
    assert not TraceSummary.objects.filter(job=job).exists()
    assert TraceSummary.objects.filter(job__model=mine).exists()  # on the console's route
    done.refresh_from_db()
    assert (done.status, done.failure, bytes(done.points)) == ("FAILED", migration.REDONE, b"")
    assert Source.of_job(job).ensure() == [] and TraceSummary.objects.filter(job=job).count() == 1
