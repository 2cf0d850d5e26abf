import gymnasium
import pytest
from django.core.management import call_command
from django.urls import reverse

import simulator
from simulator import tracks as simulator_tracks
from simulator.spectator import view_image
from training.models import RLModel, Track, Vehicle

pytestmark = pytest.mark.django_db


def test_loadtracks_mirrors_the_simulator_catalogue_and_can_run_again(capsys):
    call_command("loadtracks")
    call_command("loadtracks")
    assert list(Track.objects.values_list("name", flat=True)) == simulator_tracks.names()
    oval = Track.objects.get(name="pitlane-oval")
    assert oval.length_m == 16.5
    assert oval.directions == ["Counter-clockwise", "Clockwise"]
    assert Track.objects.get(name="championship-circuit").directions == ["Counter-clockwise"]
    assert "8 built-in tracks loaded" in capsys.readouterr().out


def test_a_racer_builds_a_vehicle(client, alice):
    client.force_login(alice)
    response = client.post(
        reverse("training:garage"),
        {"name": "Blue Thunder", "shell_colour": "#0969da", "camera": "STEREO_CAMERAS",
         "lidar": "SECTOR_LIDAR"},
        follow=True,
    )  # fmt: skip
    assert "Blue Thunder is in your garage." in response.text
    vehicle = Vehicle.objects.get(owner=alice)
    assert vehicle.sensors == ["STEREO_CAMERAS", "SECTOR_LIDAR"]


def test_a_vehicle_name_is_unique_per_racer_and_the_form_keeps_its_input(client, alice, bob):
    Vehicle.objects.create(owner=bob, name="Rocket")
    Vehicle.objects.create(owner=alice, name="Rocket")
    client.force_login(alice)
    response = client.post(
        reverse("training:garage"),
        {"name": "rocket", "shell_colour": "#d1242f", "camera": "FRONT_FACING_CAMERA"},
    )
    assert response.status_code == 400
    assert "You already have a vehicle named “rocket”" in response.text
    assert 'value="rocket"' in response.text
    assert Vehicle.objects.filter(owner=alice).count() == 1


def test_a_racer_sees_only_their_own_vehicles(client, alice, bob):
    Vehicle.objects.create(owner=bob, name="Bobs-car")
    client.force_login(alice)
    response = client.get(reverse("training:garage"))
    assert "Bobs-car" not in response.text
    assert "Your garage is empty." in response.text


def test_the_models_page_lists_the_tracks_to_train_on(client, alice, tracks):
    client.force_login(alice)
    response = client.get(reverse("training:model-list"))
    assert "You have no models yet." in response.text
    assert "Clover Loop" in response.text
    assert "24.00 m long" in response.text
    assert response.text.count('src="/tracks/') == 8


def test_a_track_preview_is_a_cacheable_png(client):
    response = client.get(reverse("training:track-preview", args=["hairpin-alley"]))
    assert response.status_code == 200
    assert response["Content-Type"] == "image/png"
    assert "max-age=86400" in response["Cache-Control"]
    assert b"".join(response.streaming_content).startswith(b"\x89PNG")


def test_an_unknown_track_preview_is_a_404(client):
    assert client.get(reverse("training:track-preview", args=["monza"])).status_code == 404


def test_a_models_car_has_its_vehicles_colour_in_the_video(client, alice, bob, tracks):
    from tests.training.test_model_pages import form_data

    red = Vehicle.objects.create(owner=alice, name="red-one", shell_colour="#d1242f")
    theirs = Vehicle.objects.create(owner=bob, name="not-yours")
    client.force_login(alice)
    refused = client.post(reverse("training:model-create"), form_data(vehicle=theirs.pk))
    assert refused.status_code == 400  # another racer's vehicle is not a choice
    response = client.post(reverse("training:model-create"), form_data(vehicle=red.pk))
    assert response.status_code == 302
    model = RLModel.objects.get(name="first-model")
    assert model.vehicle == red and model.shell_colour == "#d1242f"

    def reddish_pixels(settings: dict) -> int:
        env = gymnasium.make(simulator.ENV_ID, **settings)
        env.reset(seed=1)
        frame = view_image(env.unwrapped, "spectator").astype(int)
        env.close()
        blue, green, red = frame[..., 0], frame[..., 1], frame[..., 2]
        return int(((red > 150) & (green < 90) & (blue < 90)).sum())

    painted = reddish_pixels(model.environment_settings())
    black = reddish_pixels({**model.environment_settings(), "car_colour": (40, 35, 31)})
    assert painted > 300 and black < painted / 10  # the car, seen from behind, and its map dot
