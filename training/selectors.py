"""Reads for the training app."""

from __future__ import annotations

from django.contrib.auth.models import AbstractBaseUser
from django.db.models import QuerySet

from training.models import RLModel, Track, Vehicle


def models_for_racer(*, racer: AbstractBaseUser) -> QuerySet[RLModel]:
    return RLModel.objects.filter(owner=racer).select_related("track")


def tracks_available() -> QuerySet[Track]:
    return Track.objects.all()


def vehicles_for_racer(*, racer: AbstractBaseUser) -> QuerySet[Vehicle]:
    return Vehicle.objects.filter(owner=racer)
