from django.apps import AppConfig


class TrainingConfig(AppConfig):
    name = "training"
    verbose_name = "Training"

    def ready(self) -> None:
        from simulator import tracks

        # Tracks staff added live in the Track table: let the simulator find them by name in this
        # process (web, workers). A sandbox child gets them inline (sandbox).
        tracks.register_resolver(added_track)


def added_track(name: str) -> dict | None:
    """An added track as the simulator loads it inline (its route file's bytes and metadata), or
    None where no track was added by that name."""
    from django.db import DatabaseError

    from training.models import Direction, Track

    fields = (
        "name",
        "display_name",
        "description",
        "difficulty",
        "counterclockwise",
        "clockwise",
        "route",
    )
    try:
        row = Track.objects.filter(name=name, added_at__isnull=False).values(*fields).first()
    except DatabaseError:  # no database here (a command run before `migrate`): built-ins only
        return None
    if row is None:
        return None
    return {
        "name": row["name"],
        "display_name": row["display_name"],
        "route": bytes(row["route"]),
        "directions": [d.value for d in Direction if row[d.value]],
        "description": row["description"],
        "difficulty": row["difficulty"],
    }
