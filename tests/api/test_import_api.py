"""The API's import, with the import page's steps: an archive with its weights arrives at once;
one that would train is previewed (the archive kept for the racer), then confirmed with the
racer's changes, checked as the page checks them, or cancelled."""

from __future__ import annotations

import pytest
from django.core.files.uploadedfile import SimpleUploadedFile

from archives.models import KeptUpload
from tests.helpers.accounts import api_token
from tests.helpers.archives import CHECKED_IMPORT, deepracer_folder, virtual_archive
from tests.helpers.models import ready_model
from training.models import RLModel

IMPORT = "/api/v1/models/import"
pytestmark = CHECKED_IMPORT


def posted(client, token: dict, data: bytes, name: str = "", filename="model.tar.gz"):
    archive = SimpleUploadedFile(filename, data, content_type="application/gzip")
    return client.post(IMPORT, {"archive": archive, "name": name}, **token)


def test_an_archive_to_train_is_previewed_then_confirmed_with_the_racers_changes(
    alice, bob, tracks, client
):
    token = api_token(alice, "read", "train")
    preview = posted(client, token, deepracer_folder(WORLD_NAME="Oval_track"), "from-drfc")
    assert preview.status_code == 200, preview.content
    shown = preview.json()
    assert shown["settings"]["name"] == "from-drfc" and shown["settings"]["track"] == "Oval_track"
    assert shown["problems"] == {} and not RLModel.objects.exists()
    kept = shown["kept"]

    bobs = client.post(  # the archive is kept for its racer alone
        f"{IMPORT}/confirm", {"kept": kept}, "application/json", **api_token(bob, "train")
    )
    assert bobs.status_code == 409 and bobs.json()["code"] == "gone"
    refused = client.post(
        f"{IMPORT}/confirm", {"kept": kept, "max_minutes": 5}, "application/json", **token
    )
    assert refused.status_code == 400 and "max_minutes" in refused.json()["errors"]
    created = client.post(
        f"{IMPORT}/confirm", {"kept": kept, "max_minutes": 12}, "application/json", **token
    )
    assert created.status_code == 201, created.content
    model = RLModel.objects.get(owner=alice)
    assert created.json()["id"] == model.pk and model.max_minutes == 12
    assert model.status in (RLModel.Status.QUEUED, RLModel.Status.TRAINING)
    assert not KeptUpload.objects.exists()  # used, and gone
    again = client.post(f"{IMPORT}/confirm", {"kept": kept}, "application/json", **token)
    assert again.status_code == 409 and "choose it again" in again.json()["message"]


@pytest.mark.slow  # exports and imports the weights
def test_an_archive_with_weights_arrives_at_once_and_a_bad_one_is_refused_in_words(
    alice, tracks, client
):
    token = api_token(alice, "read", "train")
    archive = virtual_archive(ready_model(alice, name="original"))
    arrived = posted(client, token, archive, "again")
    assert arrived.status_code == 201, arrived.content
    assert arrived.json()["status"] == "READY" and arrived.json()["name"] == "again"

    refused = posted(client, token, b"not an archive", filename="x.tar.gz")
    assert refused.status_code == 400 and refused.json()["code"] == "refused"
    assert "archive" in refused.json()["message"]
    taken = posted(client, token, archive, "again")  # the name is checked before the archive
    assert taken.status_code == 400 and "name" in taken.json()["errors"]
    reader = posted(client, api_token(alice, "read"), archive)
    assert reader.status_code == 403

    held = posted(client, token, deepracer_folder(WORLD_NAME="Oval_track"))
    assert held.status_code == 200 and KeptUpload.objects.filter(racer=alice).exists()
    cancelled = client.delete(IMPORT, **token)
    assert cancelled.json() == {"cancelled": "model.tar.gz"}
    assert not KeptUpload.objects.exists()
