"""Summaries and re-scorings of a model that drives its own route file (``RLModel.world_name``: a
DeepRacer for Cloud import's bare WORLD_NAME) were made on the console's route for its track,
metres away and with other waypoints (issue 54): the summaries go, to be made again on the route
the model drove when its Analysis tab is next opened (``Source.ensure``), and the re-scorings that
finished say so and are scored again on request."""

from django.db import migrations
from django.db.models import F, Q

REDONE = (
    "Scored on the console's route for this track, not the route file the model drove: "
    "re-score it to see its rewards on that route."
)


def forget_what_was_made_on_the_consoles_route(apps, schema_editor):
    on_own_route = Q(job__model__world_name__gt="") | Q(
        evaluation__model__world_name__gt="",
        evaluation__track_id=F("evaluation__model__track_id"),
    )
    apps.get_model("analysis", "TraceSummary").objects.filter(on_own_route).delete()
    apps.get_model("analysis", "Rescoring").objects.filter(on_own_route, status="DONE").update(
        status="FAILED", failure=REDONE, episodes={}, points=b"", point_counts={}
    )


class Migration(migrations.Migration):
    dependencies = [
        ("analysis", "0002_rescoring_started_at"),
        ("training", "0021_world_name"),
    ]

    operations = [
        migrations.RunPython(forget_what_was_made_on_the_consoles_route, migrations.RunPython.noop),
    ]
