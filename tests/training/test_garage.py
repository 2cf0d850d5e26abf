import re

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
    said = f"{len(simulator_tracks.names())} built-in tracks loaded: 8 of Pitlane's and 70 of "
    assert said + "DeepRacer's." in capsys.readouterr().out


def test_a_racer_builds_a_vehicle(client, alice):
    client.force_login(alice)
    response = client.post(
        reverse("training:garage"),
        {
            "name": "Blue Thunder",
            "shell_colour": "#0969da",
            "camera": "STEREO_CAMERAS",
            "lidar": "SECTOR_LIDAR",
        },
        follow=True,
    )
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
    assert response.text.count('src="/tracks/') == len(tracks)


def cards(page: str) -> list[str]:
    """The Tracks list's cards, in page order, by their names."""
    return re.findall(r'src="/tracks/([\w-]+)\.png"', page)


def test_the_tracks_list_searches_and_sorts_without_javascript(client, alice, tracks):
    client.force_login(alice)
    url = reverse("training:model-list")
    found = cards(client.get(url, {"q": "speedway 2022"}).text)
    assert found[:2] == ["2022_april_open", "2022_april_pro"]
    assert "reInvent2019_track" not in found  # Smile Speedway, of 2020: every word must match
    assert (
        len(found) == Track.objects.filter(display_name__icontains="speedway", season=2022).count()
    )
    assert cards(client.get(url, {"q": "pitlane"}).text) == simulator_tracks.names(origin="pitlane")
    by_length = cards(client.get(url, {"sort": "length"}).text)
    lengths = dict(Track.objects.values_list("name", "length_m"))
    assert [lengths[n] for n in by_length] == sorted(lengths.values())
    assert by_length[-1] == "penbay_pro"  # 89.24 m, the longest
    by_season = cards(client.get(url, {"sort": "season"}).text)
    assert by_season[:8] == simulator_tracks.names(origin="pitlane")  # Pitlane's, then 2024
    seasons = dict(Track.objects.values_list("name", "season"))
    assert [seasons[n] for n in by_season[8:]] == sorted(
        (s for s in seasons.values() if s), reverse=True
    )  # 2024 first, "2019 and earlier" last
    page = client.get(url, {"q": "monza"}).text
    assert "Expects:" not in page  # the includes' comments stay in them
    assert "No track matches “monza”." in page and 'aria-pressed="true">Catalogue' in page


def test_a_nul_in_the_tracks_search_is_dropped(client, alice, tracks):
    """PostgreSQL refuses a NUL in a query's text: ?q=%00 was a server error there."""
    client.force_login(alice)
    response = client.get(reverse("training:model-list"), {"q": "smile\x00"})
    assert response.status_code == 200
    assert cards(response.text) == ["reInvent2019_track"] and "\x00" not in response.text


def test_a_track_preview_is_a_cacheable_png(client):
    response = client.get(reverse("training:track-preview", args=["hairpin-alley"]))
    assert response.status_code == 200
    assert response["Content-Type"] == "image/png"
    assert "max-age=86400" in response["Cache-Control"]
    assert b"".join(response.streaming_content).startswith(b"\x89PNG")


def test_an_unknown_track_preview_is_a_404(client):
    assert client.get(reverse("training:track-preview", args=["monza"])).status_code == 404


def test_a_models_car_has_its_vehicles_colour_in_the_video(client, alice, bob, tracks):
    from tests.helpers.training import form_data

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


def _model_on(vehicle, name: str = "on-the-car") -> RLModel:
    from training.rewards import EXAMPLES
    from training.services import model_create

    return model_create(
        owner=vehicle.owner,
        validate_reward=False,
        settings={
            "name": name,
            "track": "rookie-loop",
            "reward_function": EXAMPLES[0].source,
            "vehicle": vehicle,
            "sensors": vehicle.sensors,
        },
    )


def test_the_garage_offers_shell_colours_as_named_swatches(client, alice):
    client.force_login(alice)
    response = client.get(reverse("training:garage"))
    swatches = response.text.count('class="swatch-choice"')
    assert swatches == len(Vehicle.ShellColour.choices) == 8
    assert 'value="#d1242f" id="id_shell_colour_2" style="--shell: #d1242f"' in response.text
    assert '<span class="visually-hidden">Red</span>' in response.text


def test_a_racer_renames_and_repaints_a_vehicle(client, alice):
    vehicle = Vehicle.objects.create(owner=alice, name="Rocket", shell_colour="#1f2328")
    client.force_login(alice)
    url = reverse("training:vehicle-edit", args=[vehicle.pk])
    page = client.get(url)
    assert 'value="Rocket"' in page.text and 'value="#1f2328" id="id_shell_colour_0"' in page.text
    response = client.post(
        url,
        {"name": "Comet", "shell_colour": "#2da44e", "camera": "STEREO_CAMERAS", "lidar": "LIDAR"},
        follow=True,
    )
    assert "Comet is saved." in response.text
    vehicle.refresh_from_db()
    assert (vehicle.name, vehicle.shell_colour) == ("Comet", "#2da44e")
    assert vehicle.sensors == ["STEREO_CAMERAS", "LIDAR"]  # no model yet: sensors may change


def test_an_edit_with_a_taken_name_says_so_and_keeps_what_was_typed(client, alice):
    Vehicle.objects.create(owner=alice, name="Taken")
    vehicle = Vehicle.objects.create(owner=alice, name="Rocket")
    client.force_login(alice)
    url = reverse("training:vehicle-edit", args=[vehicle.pk])
    response = client.post(
        url,
        {"name": "taken", "shell_colour": "#0969da", "camera": "FRONT_FACING_CAMERA", "lidar": ""},
    )
    assert response.status_code == 400
    assert "You already have a vehicle named “taken”" in response.text
    assert 'value="taken"' in response.text
    assert (
        'value="#0969da" id="id_shell_colour_6" style="--shell: #0969da" checked' in response.text
    )
    assert "<h1>Edit Rocket</h1>" in response.text
    kept = client.post(
        url,
        {"name": "rocket", "shell_colour": "#0969da", "camera": "FRONT_FACING_CAMERA", "lidar": ""},
    )
    assert kept.status_code == 302  # its own name, in another case, is not taken
    no_name = client.post(url, {"name": " ", "camera": "FRONT_FACING_CAMERA", "lidar": ""})
    assert "Give your vehicle a name." in no_name.text
    assert "Choose a shell colour." in no_name.text
    odd = client.post(url, {"name": "Rocket", "shell_colour": "#123456", "camera": "LIDAR"})
    assert "Choose one of the shell colours." in odd.text
    assert "Choose one of the cameras." in odd.text


def test_a_vehicle_with_models_keeps_its_sensors_and_says_why(client, alice, tracks):
    vehicle = Vehicle.objects.create(owner=alice, name="Rocket", camera="FRONT_FACING_CAMERA")
    _model_on(vehicle)
    client.force_login(alice)
    url = reverse("training:vehicle-edit", args=[vehicle.pk])
    page = client.get(url)
    assert "Locked: models were trained on these sensors" in page.text
    assert page.text.count("disabled") >= 3  # two camera radios and the lidar list
    response = client.post(
        url,
        {
            "name": "Rocket-2",
            "shell_colour": "#f28c28",
            "camera": "STEREO_CAMERAS",
            "lidar": "LIDAR",
        },
    )
    assert response.status_code == 302
    vehicle.refresh_from_db()
    assert vehicle.name == "Rocket-2" and vehicle.shell_colour == "#f28c28"
    assert vehicle.sensors == ["FRONT_FACING_CAMERA"]


def test_the_update_service_refuses_new_sensors_once_a_model_was_trained(alice, tracks):
    from training.services import VehicleSensorsLocked, vehicle_update

    vehicle = Vehicle.objects.create(owner=alice, name="Rocket")
    _model_on(vehicle)
    with pytest.raises(VehicleSensorsLocked, match="build a new vehicle"):
        vehicle_update(
            vehicle=vehicle,
            name="Rocket",
            shell_colour=vehicle.shell_colour,
            camera="STEREO_CAMERAS",
            lidar="",
        )


def test_a_racer_deletes_a_vehicle_after_confirming_and_its_models_keep_their_settings(
    client, alice, tracks
):
    vehicle = Vehicle.objects.create(
        owner=alice,
        name="Rocket",
        shell_colour="#d1242f",
        camera="STEREO_CAMERAS",
        lidar="SECTOR_LIDAR",
    )
    model = _model_on(vehicle)
    client.force_login(alice)
    detail = client.get(reverse("training:model-detail", args=[model.pk]))
    assert f'<a href="{reverse("training:garage")}">Rocket</a>' in detail.text
    url = reverse("training:vehicle-delete", args=[vehicle.pk])
    confirm = client.get(url)
    assert "Delete Rocket?" in confirm.text
    assert "1 model was trained on this vehicle" in confirm.text and "on-the-car" in confirm.text
    assert Vehicle.objects.filter(pk=vehicle.pk).exists()  # asking deletes nothing
    response = client.post(url, follow=True)
    assert "Rocket has left your garage." in response.text
    assert not Vehicle.objects.filter(pk=vehicle.pk).exists()
    model.refresh_from_db()
    assert model.vehicle is None
    assert (model.sensors, model.shell_colour) == (["STEREO_CAMERAS", "SECTOR_LIDAR"], "#d1242f")
    detail = client.get(reverse("training:model-detail", args=[model.pk]))
    assert "No vehicle" in detail.text and "Red shell" in detail.text


def test_a_racer_cannot_edit_or_delete_another_racers_vehicle(client, alice, bob):
    theirs = Vehicle.objects.create(owner=bob, name="Bobs-car")
    client.force_login(alice)
    for name in ("training:vehicle-edit", "training:vehicle-delete"):
        url = reverse(name, args=[theirs.pk])
        assert client.get(url).status_code == 404
        assert (
            client.post(
                url, {"name": "mine", "shell_colour": "#d1242f", "camera": "FRONT_FACING_CAMERA"}
            ).status_code
            == 404
        )
    theirs.refresh_from_db()
    assert theirs.name == "Bobs-car"


def test_the_garage_lists_each_vehicles_models_and_its_edit_and_delete_links(client, alice, tracks):
    vehicle = Vehicle.objects.create(owner=alice, name="Rocket")
    _model_on(vehicle, "one")
    _model_on(vehicle, "two")
    client.force_login(alice)
    response = client.get(reverse("training:garage"))
    assert "<td>2</td>" in response.text
    assert reverse("training:vehicle-edit", args=[vehicle.pk]) in response.text
    assert reverse("training:vehicle-delete", args=[vehicle.pk]) in response.text
