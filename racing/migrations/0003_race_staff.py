"""The "Race staff" group: league staff who manage seasons, events, submissions and divisions in
the admin, and nothing else (users and the rest stay with superusers)."""

from django.contrib.auth.management import create_permissions
from django.db import migrations

GROUP = "Race staff"
MODELS = ("season", "event", "submission", "lap", "ranking", "racer")


def create_group(apps, schema_editor):
    for app_config in apps.get_app_configs():
        app_config.models_module = True
        create_permissions(app_config, verbosity=0)
        app_config.models_module = None
    Group = apps.get_model("auth", "Group")
    Permission = apps.get_model("auth", "Permission")
    group, _ = Group.objects.get_or_create(name=GROUP)
    group.permissions.set(
        Permission.objects.filter(content_type__app_label="racing", content_type__model__in=MODELS)
    )


def remove_group(apps, schema_editor):
    apps.get_model("auth", "Group").objects.filter(name=GROUP).delete()


class Migration(migrations.Migration):
    dependencies = [
        ("racing", "0002_league"),
        ("auth", "0012_alter_user_first_name_max_length"),
        ("contenttypes", "0002_remove_content_type_name"),
    ]

    operations = [migrations.RunPython(create_group, remove_group)]
