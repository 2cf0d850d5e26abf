"""Tracks staff add from DeepRacer route files: loadtracks, the admin's upload, the preview, and
models trained on them (validated in the web process, driven in a sandbox child)."""

import io

import numpy as np
import pytest
from django.core.files.uploadedfile import SimpleUploadedFile
from django.core.management import CommandError, call_command
from django.urls import reverse

from tests import routes
from tests.helpers.sandbox import driving
from tests.helpers.tracks import claiming, upload
from tests.helpers.training import form_data
from training.models import RLModel, Track
from training.services import TrackRefused, track_add, tracks_sync

pytestmark = pytest.mark.django_db
PNG = b"\x89PNG\r\n\x1a\n"


def route_file(tmp_path, kind: str = "clockwise"):
    path = tmp_path / f"{kind}.npy"
    np.save(path, routes.ROUTES[kind]())
    return path


def loadtracks(*args) -> str:
    out = io.StringIO()
    call_command("loadtracks", *map(str, args), stdout=out)
    return out.getvalue()


def test_loadtracks_adds_a_route_file_with_its_length_width_and_preview(tmp_path, tracks, client):
    path = route_file(tmp_path)
    said = loadtracks(
        path,
        "--name",
        "H_track",
        "--display-name",
        "H track",
        "--directions",
        "clockwise",
        "--difficulty",
        "advanced",
    )
    assert said == ("Added H track (H_track): 20.68 m long, 1.07 m wide, driven clockwise.\n")
    track = Track.objects.get(name="H_track")
    assert not track.builtin and track.added_at is not None
    assert (track.length_m, track.width_m) == (pytest.approx(20.68), pytest.approx(1.067))
    assert (track.clockwise, track.counterclockwise, track.difficulty) == (True, False, "advanced")
    assert bytes(track.route) == path.read_bytes()
    assert bytes(track.preview).startswith(PNG)
    assert track.position > max(t.position for t in tracks)
    response = client.get(reverse("training:track-preview", args=["H_track"]))
    assert response.status_code == 200 and response["Content-Type"] == "image/png"
    assert b"".join(response) == bytes(track.preview)
    # Running the built-in sync again leaves it as it is.
    assert f"{len(tracks)} built-in tracks loaded" in loadtracks()
    assert Track.objects.get(name="H_track").length_m == pytest.approx(20.68)


def test_loadtracks_refuses_what_it_cannot_add_in_the_loaders_words(tmp_path, tracks):
    with pytest.raises(
        CommandError,
        match=r"^border_crosses_itself\.npy: The inner border of "
        r"this track crosses itself \(between waypoints",
    ):
        loadtracks(route_file(tmp_path, "border_crosses_itself"), "--name", "kinked")
    with pytest.raises(CommandError, match=r"not_a_number\.npy: Waypoint 7 of the route file"):
        loadtracks(route_file(tmp_path, "not_a_number"), "--name", "nan")
    good = route_file(tmp_path, "repeated_point")
    with pytest.raises(CommandError, match="pitlane-oval is a built-in track"):
        loadtracks(good, "--name", "pitlane-oval")
    with pytest.raises(CommandError, match="A track name is 1 to 64 letters, digits"):
        loadtracks(good, "--name", "my track")
    with pytest.raises(CommandError, match="Choose the directions the track is driven"):
        loadtracks(good, "--name", "loop", "--directions", "sideways")
    with pytest.raises(CommandError, match=r"Cannot read .*missing\.npy"):
        loadtracks(tmp_path / "missing.npy", "--name", "loop")
    assert "Added repeated_point (repeated_point)" in loadtracks(good)
    with pytest.raises(CommandError, match=r"already a track named repeated_point .*replace it"):
        loadtracks(good)
    said = loadtracks(good, "--replace", "--display-name", "Loop", "--difficulty", "beginner")
    assert said.startswith("Replaced Loop (repeated_point)")
    assert Track.objects.get(name="repeated_point").difficulty == "beginner"
    assert not Track.objects.filter(name__in=["kinked", "nan", "my track", "loop"]).exists()


def test_an_added_track_is_never_clobbered_by_the_built_in_sync(tracks):
    Track.objects.filter(name="s-bend").delete()
    row = track_add(
        name="s-bend-2",
        display_name="Mine",
        route=routes.route_bytes("clockwise"),
        directions=["clockwise"],
    )
    Track.objects.filter(pk=row.pk).update(name="s-bend")  # as if the catalogue later took it
    tracks_sync()
    kept = Track.objects.get(name="s-bend")
    assert (kept.display_name, kept.builtin) == ("Mine", False)
    with pytest.raises(
        TrackRefused, match=r"^name: s-bend is a built-in track; choose another name"
    ):
        track_add(
            name="s-bend",
            display_name="",
            route=routes.route_bytes("clockwise"),
            directions=["clockwise"],
        )


def test_staff_add_a_track_by_uploading_its_route_file_in_the_admin(admin_client, tracks):
    form = admin_client.get(reverse("admin:training_track_add")).text
    assert 'enctype="multipart/form-data"' in form and 'name="route_file"' in form
    assert 'name="directions"' in form and 'name="difficulty"' in form
    response = upload(admin_client, "repeated_border_point", "my_arctic_open")
    assert response.status_code == 302
    track = Track.objects.get(name="my_arctic_open")
    assert (track.display_name, track.description, track.directions) == (
        "Upload",
        "From the admin",
        ["Counter-clockwise", "Clockwise"],
    )
    assert track.added_by.username == "marshal"
    assert bytes(track.preview).startswith(PNG)
    page = admin_client.get(reverse("admin:training_track_change", args=[track.pk]))
    assert 'name="display_name"' in page.text and "Top-down map of Upload" in page.text
    added = admin_client.get(reverse("admin:training_track_changelist") + "?origin=added").text
    assert "my_arctic_open" in added and "pitlane-oval" not in added
    change = reverse("admin:training_track_change", args=[track.pk])
    fields = {"display_name": "Arctic Open", "description": "", "difficulty": "expert"}
    refused = admin_client.post(change, fields)
    assert "Choose at least one direction racers may drive it." in refused.text
    assert admin_client.post(change, {**fields, "clockwise": "on"}).status_code == 302
    track = Track.objects.get(name="my_arctic_open")
    assert (track.display_name, track.directions, track.difficulty) == (
        "Arctic Open",
        ["Clockwise"],
        "expert",
    )
    assert track.added_by.username == "marshal" and bytes(track.preview).startswith(PNG)


def test_a_bad_route_file_uploaded_in_the_admin_shows_the_loaders_message(admin_client, tracks):
    response = upload(admin_client, "borders_cross", "twisted")
    assert response.status_code == 200
    assert "The inner and outer borders of this track cross each other" in response.text
    response = upload(admin_client, "wrong_shape", "flat")
    assert "This one has shape (61, 4)." in response.text
    assert not Track.objects.filter(name__in=["twisted", "flat"]).exists()


def test_a_route_file_whose_header_claims_terabytes_is_refused_in_the_admin_not_a_500(
    admin_client, tracks
):
    data = {
        "route_file": SimpleUploadedFile("huge.npy", claiming((10**12, 6))),
        "name": "huge",
        "difficulty": "beginner",
        "directions": ["counterclockwise"],
    }
    response = admin_client.post(reverse("admin:training_track_add"), data)
    assert response.status_code == 200
    assert "is cut short or damaged: its header says it holds 6,000,000,000,000 values" in (
        response.text
    )
    assert not Track.objects.filter(name="huge").exists()


def test_built_in_tracks_are_read_only_in_the_admin(admin_client, tracks):
    builtin = Track.objects.get(name="pitlane-oval")
    url = reverse("admin:training_track_change", args=[builtin.pk])
    page = admin_client.get(url)
    assert page.status_code == 200 and 'name="display_name"' not in page.text
    assert admin_client.post(url, {"display_name": "Renamed"}).status_code == 403
    delete = reverse("admin:training_track_delete", args=[builtin.pk])
    assert admin_client.post(delete, {"post": "yes"}).status_code == 403


@pytest.mark.slow
def test_a_model_on_an_added_track_validates_its_reward_and_drives_it_in_the_sandbox(
    client, alice, tracks
):
    track_add(
        name="H_track",
        display_name="H track",
        route=routes.route_bytes("clockwise"),
        directions=["clockwise"],
    )
    client.force_login(alice)
    page = client.get(reverse("training:model-create")).text
    assert 'value="H_track"' in page
    data = form_data(track="H_track", direction="clockwise")
    response = client.post(reverse("training:model-create"), data)
    assert response.status_code == 302, response.text
    model = RLModel.objects.get(owner=alice)
    assert model.track.name == "H_track"
    # The sandbox child has no database: the parent sends the track inline.
    with driving({"track": model.track.name, "direction": model.direction}) as sandbox:
        sandbox.load(
            "def reward_function(params):\n"
            "    print(round(params['track_length'], 2))\n"
            "    return 1.0\n"
        )
        result = sandbox.episode("random")
    assert result["summary"]["steps"] >= 1
    assert set(sandbox.logs) == {"20.68"}, sandbox.logs


def test_a_deepracer_route_name_is_refused_as_it_would_load_the_catalogue_track(tracks):
    """load() finds a WORLD_NAME in the catalogue before any added track, so 2022_april_open_cw
    stored as an added track would never be the one driven."""
    refused = r"^name: 2022_april_open_cw is DeepRacer's name for the built-in Ace Speedway"
    with pytest.raises(TrackRefused, match=refused + r" \(clockwise\); choose another name"):
        track_add(
            name="2022_april_open_cw",
            display_name="",
            directions=["clockwise"],
            route=routes.route_bytes("clockwise"),
        )
    assert not Track.objects.filter(name="2022_april_open_cw").exists()
