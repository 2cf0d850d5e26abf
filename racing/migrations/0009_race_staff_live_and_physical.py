"""The "Race staff" group also runs live races and physical events in the admin: their sessions,
queue entries and timed runs."""

from django.contrib.auth.management import create_permissions
from django.db import migrations

GROUP = "Race staff"
MODELS = ("livesession", "liveentry", "physicalrun")


def grant(apps, schema_editor):
    for app_config in apps.get_app_configs():
        app_config.models_module = True
        create_permissions(app_config, verbosity=0)
        app_config.models_module = None
    Group = apps.get_model("auth", "Group")
    Permission = apps.get_model("auth", "Permission")
    group, _ = Group.objects.get_or_create(name=GROUP)
    group.permissions.add(
        *Permission.objects.filter(content_type__app_label="racing", content_type__model__in=MODELS)
    )


class Migration(migrations.Migration):
    dependencies = [
        ("racing", "0008_live_sessions"),
    ]

    operations = [migrations.RunPython(grant, migrations.RunPython.noop)]
