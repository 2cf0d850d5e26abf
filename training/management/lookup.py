"""What the model commands share: finding a model by its name (or number) and racer."""

from __future__ import annotations

from django.contrib.auth import get_user_model
from django.core.management.base import CommandError

from training.models import RLModel


def find_model(name: str, owner: str | None) -> RLModel:
    """The model called ``name`` (or numbered so), of ``owner`` when given; ``CommandError``
    when there is none, or several racers have one of that name."""
    models = RLModel.objects.select_related("owner", "track")
    if owner:
        racer = find_racer(owner)
        models = models.filter(owner=racer)
    found = list(models.filter(pk=int(name)) if name.isdigit() else models.filter(name=name))
    if not found:
        raise CommandError(f"No model named {name!r}" + (f" of {owner}." if owner else "."))
    if len(found) > 1:
        raise CommandError(f"Several racers have a model named {name!r}; add --owner.")
    return found[0]


def find_racer(username: str):
    racer = get_user_model().objects.filter(username=username).first()
    if racer is None:
        raise CommandError(f"No racer named {username!r}.")
    return racer
