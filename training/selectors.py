"""Reads for the training app."""

from __future__ import annotations

from dataclasses import dataclass

from django.contrib.auth.models import AbstractBaseUser
from django.core.files.storage import default_storage
from django.db.models import QuerySet

from training import artifacts
from training.models import RLModel, Track, Vehicle


def models_for_racer(*, racer: AbstractBaseUser) -> QuerySet[RLModel]:
    return RLModel.objects.filter(owner=racer).select_related("track")


def tracks_available() -> QuerySet[Track]:
    return Track.objects.all()


def vehicles_for_racer(*, racer: AbstractBaseUser) -> QuerySet[Vehicle]:
    return Vehicle.objects.filter(owner=racer)


@dataclass(frozen=True)
class ModelFile:
    relative: str
    label: str


def model_files(*, model: RLModel) -> list[ModelFile]:
    """The model's downloadable logs: the metrics JSON and each iteration's simulation trace."""
    files = []
    prefix = artifacts.path(model, "")
    if default_storage.exists(prefix + "metrics/training_metrics.json"):
        files.append(ModelFile("metrics/training_metrics.json", "Training metrics (JSON)"))
    try:
        _, names = default_storage.listdir(prefix + "training-simtrace")
    except FileNotFoundError:
        names = []
    iterations = sorted(int(n.split("-")[0]) for n in names if n.split("-")[0].isdigit())
    for number in iterations:
        relative = f"training-simtrace/{number}-iteration.csv"
        files.append(ModelFile(relative, f"Simulation trace, iteration {number}"))
    return files
