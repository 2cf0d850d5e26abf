"""Writes for the training app."""

from __future__ import annotations

from django.contrib.auth.models import AbstractBaseUser
from django.db import transaction

from simulator import tracks as simulator_tracks
from training.models import Direction, Track, Vehicle


@transaction.atomic
def tracks_sync() -> list[Track]:
    """Mirror the simulator's built-in tracks into the database: add new ones, update the rest.

    A track that has left the catalogue stays (models may still refer to it).
    """
    synced = []
    for position, name in enumerate(simulator_tracks.names()):
        track = simulator_tracks.load(name)
        row, _ = Track.objects.update_or_create(
            name=name,
            defaults={
                "display_name": track.display_name,
                "description": track.description,
                "difficulty": track.difficulty,
                "length_m": round(track.length, 2),
                "width_m": round(track.width, 3),
                "counterclockwise": Direction.COUNTERCLOCKWISE in track.directions,
                "clockwise": Direction.CLOCKWISE in track.directions,
                "position": position,
            },
        )
        synced.append(row)
    return synced


def vehicle_create(
    *, owner: AbstractBaseUser, name: str, shell_colour: str, camera: str, lidar: str
) -> Vehicle:
    vehicle = Vehicle(owner=owner, name=name, shell_colour=shell_colour, camera=camera, lidar=lidar)
    vehicle.full_clean()
    vehicle.save()
    return vehicle
