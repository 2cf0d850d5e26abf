"""The camera lens a racer picks for a model: DeepRacer's simulated camera by default, or the
physical car's wide lens. It travels from the create-model page into the environment the model
trains and races in, onto the model's page, and through our own export into an import."""

import importlib
import io
import json

import gymnasium
import pytest
from django.urls import reverse

import simulator
from archives import exports, imports
from simulator.camera import CAR_FOV, SIMAPP_FOV
from tests.helpers.archives import deepracer_export, tar_gz
from tests.helpers.training import post
from tests.helpers.training import settings as training_settings
from training import configuration, leases
from training.forms import ModelCreateForm
from training.models import CameraLens, RLModel, TrainingJob

pytestmark = pytest.mark.django_db


def test_the_lens_a_racer_picks_travels_from_the_form_into_the_environment(client, alice, tracks):
    response = post(client, alice, camera_lens="wide")
    model = RLModel.objects.get(owner=alice)
    assert response.status_code == 302 and model.camera_lens == CameraLens.WIDE
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
    assert env.unwrapped.config["camera_fov"] == CAR_FOV
    page = client.get(reverse("training:model-detail", args=[model.pk]))
    assert "The physical car&#x27;s wide lens (120°)" in page.text


def test_a_model_made_without_choosing_sees_through_deepracers_simulated_camera(
    client, alice, tracks
):
    post(client, alice)
    model = RLModel.objects.get(owner=alice)
    assert model.camera_lens == CameraLens.SIMULATOR
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
    assert env.unwrapped.config["camera_fov"] == SIMAPP_FOV


def test_a_lens_that_is_not_offered_is_refused_at_its_field_in_words(client, alice, tracks):
    words = "Choose DeepRacer&#x27;s simulated camera or the car&#x27;s wide lens."
    response = post(client, alice, camera_lens="fisheye")
    assert not RLModel.objects.filter(owner=alice).exists()
    assert words in response.text
    with pytest.raises(configuration.Invalid) as refused:
        configuration.check(
            training_settings(camera_lens="fisheye"), owner=alice, validate_reward=False
        )
    assert refused.value.errors == {"camera_lens": words.replace("&#x27;", "'")}


def test_a_clone_and_our_own_export_keep_the_lens(alice, bob, tracks):
    checked = configuration.check(
        training_settings(camera_lens="wide"), owner=alice, validate_reward=False
    )
    original = RLModel.objects.create(owner=alice, **checked.row())
    clone_page = ModelCreateForm.initial_from(configuration.ModelSettings.of(original))
    assert clone_page["camera_lens"] == CameraLens.WIDE
    # pitlane.json carries it (DeepRacer's model_metadata.json has no field for a lens).
    ours = exports.pitlane_settings(original)
    assert ours["camera_lens"] == CameraLens.WIDE
    archive = tar_gz(deepracer_export(**{"pitlane.json": json.dumps(ours).encode()}))
    imported = imports.import_model(owner=bob, archive=io.BytesIO(archive))
    assert imported.model.camera_lens == CameraLens.WIDE


def test_a_model_trained_before_deepracers_camera_says_so_on_its_page(client, alice, tracks):
    from django.apps import apps

    def trained(name: str, **job) -> RLModel:
        checked = configuration.check(
            training_settings(name=name), owner=alice, validate_reward=False
        )
        model = RLModel.objects.create(owner=alice, **checked.row())
        TrainingJob.objects.create(model=model, iterations=3, **job)
        return model

    before = trained("before")  # trained here, as every model before migration 0018
    imported = trained("imported", lease_owner=leases.IMPORTED)  # an import never trained here
    migration = importlib.import_module("training.migrations.0018_camera_lens")

    migration.mark_camera_before_deepracer(apps, None)
    since = trained("since")  # trained after the migration: with DeepRacer's camera

    said = "it now drives with DeepRacer's 64.7° camera: clone it and train the clone to adapt."
    client.force_login(alice)
    pages = {
        m.name: client.get(reverse("training:model-detail", args=[m.pk])).text
        for m in (before, imported, since)
    }
    assert said in pages["before"]
    assert said not in pages["imported"] and said not in pages["since"]


def test_a_model_trained_with_a_lidar_before_simapps_mount_says_so_on_its_page(
    client, alice, tracks
):
    from django.apps import apps

    def trained(name: str, sensors: list[str], **job) -> RLModel:
        checked = configuration.check(
            training_settings(name=name, sensors=sensors), owner=alice, validate_reward=False
        )
        model = RLModel.objects.create(owner=alice, **checked.row())
        TrainingJob.objects.create(model=model, iterations=3, **job)
        return model

    lidar = ["FRONT_FACING_CAMERA", "LIDAR"]
    before = trained("before", lidar)
    camera_only = trained("camera-only", ["FRONT_FACING_CAMERA"])
    imported = trained(
        "imported", ["FRONT_FACING_CAMERA", "SECTOR_LIDAR"], lease_owner=leases.IMPORTED
    )
    migration = importlib.import_module("training.migrations.0022_lidar_mount")

    migration.mark_lidar_before_deepracer(apps, None)
    since = trained("since", lidar)

    said = "it now reads DeepRacer's, facing backwards 0.182 m up"
    client.force_login(alice)
    pages = {
        m.name: client.get(reverse("training:model-detail", args=[m.pk])).text
        for m in (before, camera_only, imported, since)
    }
    assert said in pages["before"]
    assert not any(said in pages[name] for name in ("camera-only", "imported", "since"))
