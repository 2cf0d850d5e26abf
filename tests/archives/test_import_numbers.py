"""Numbers an imported archive brings are checked as the create-model and evaluation pages check
theirs: a seed the trainer or the database cannot take, or a hyperparameter that is not a finite
number in DeepRacer's range, is said in a racer's words, never answered with a 500."""

from __future__ import annotations

import json

import pytest
from django.core.files.uploadedfile import SimpleUploadedFile
from django.urls import reverse

from archives import exports
from tests.helpers.archives import (
    CHECKED_IMPORT,
    DEEPRACER_HYPERPARAMETERS,
    deepracer_export,
    tar_gz,
)
from training.models import RLModel, TrainingJob

pytestmark = CHECKED_IMPORT


def import_page(client, members: dict[str, bytes]):
    upload = SimpleUploadedFile("model.tar.gz", tar_gz(members))
    return client.post(reverse("archives:model-import"), {"archive": upload})


@pytest.mark.parametrize(
    "seed", ["-1", "2147483648", "1099511627776", "18446744073709551616", "1e300", '"x"']
)
def test_it_refuses_an_imported_seed_the_trainer_cannot_take_in_words(seed, alice, tracks, client):
    client.force_login(alice)
    response = import_page(
        client, deepracer_export(**{exports.PITLANE_SETTINGS: f'{{"seed": {seed}}}'.encode()})
    )
    assert response.status_code == 400
    assert "Seed: A seed is a whole number from 0 to 2147483647." in response.text
    assert "Traceback" not in response.text
    assert not RLModel.objects.exists() and not TrainingJob.objects.exists()


def test_it_imports_a_seed_in_range(alice, tracks, client):
    client.force_login(alice)
    members = deepracer_export(**{exports.PITLANE_SETTINGS: b'{"seed": 2147483647}'})
    preview = import_page(client, members)
    assert "Seed:" not in preview.text
    confirmed = {**preview.context["confirm"].data, "confirm": "1"}
    client.post(reverse("archives:model-import"), confirmed)
    assert RLModel.objects.get(owner=alice).seed == 2147483647


# JSON as Python's json module writes (and reads) the numbers no other JSON has.
@pytest.mark.parametrize(
    ("number", "shown"),
    [
        ("Infinity", "Infinity"),
        ("-Infinity", "-Infinity"),
        ("NaN", "NaN"),
        ("1e300", "1e+300"),
        ("-1", "-1"),
        ("1" + "0" * 400, "1" + "0" * 400),
    ],
)
def test_it_leaves_a_hyperparameter_that_is_not_a_finite_number_in_range_at_its_default(
    number, shown, alice, tracks, client
):
    given = {**DEEPRACER_HYPERPARAMETERS, "batch_size": 0, "lr": 0, "num_epochs": 0}
    text = json.dumps(given)
    for key in ("batch_size", "lr", "num_epochs"):
        text = text.replace(f'"{key}": 0', f'"{key}": {number}')
    client.force_login(alice)
    preview = import_page(client, deepracer_export(**{"hyperparameters.json": text.encode()}))
    assert preview.status_code == 200
    page = preview.text.replace("&#x27;", "'")
    for note in (
        f"batch_size {shown}. Gradient descent batch size must be one of 32, 64, 128, 256, 512. "
        "The model uses 64.",
        f"lr {shown}. Learning rate must be between 1e-08 and 0.001. The model uses 0.0003.",
        f"num_epochs {shown}. Number of epochs must be between 3 and 10. The model uses 10.",
    ):
        assert "Not carried over from hyperparameters.json: " + note in page, note
    confirmed = {**preview.context["confirm"].data, "confirm": "1"}
    client.post(reverse("archives:model-import"), confirmed)
    model = RLModel.objects.get(owner=alice)
    assert (model.hyperparameters["batch_size"], model.hyperparameters["num_epochs"]) == (64, 10)
    assert model.hyperparameters["lr"] == 0.0003
