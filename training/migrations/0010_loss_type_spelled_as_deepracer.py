"""Stored hyperparameters spell the loss type as DeepRacer does: "mean squared error", not
Pitlane's former "mse" (simapp bundle/markov/constants.py:65-69, 01f5f01)."""

from django.db import migrations


def respell(apps, old: str, new: str) -> None:
    RLModel = apps.get_model("training", "RLModel")
    for model in RLModel.objects.filter(hyperparameters__loss_type=old).only("hyperparameters"):
        model.hyperparameters["loss_type"] = new
        model.save(update_fields=["hyperparameters"])


def forwards(apps, schema_editor) -> None:
    respell(apps, "mse", "mean squared error")


def backwards(apps, schema_editor) -> None:
    respell(apps, "mean squared error", "mse")


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0009_tracks_as_data"),
    ]

    operations = [
        migrations.RunPython(forwards, backwards),
    ]
