from django.db import migrations, models

IMPORTED = "import"  # training.leases.IMPORTED: an import's record of a job that never ran here
LIDARS = ("LIDAR", "SECTOR_LIDAR")


def mark_lidar_before_deepracer(apps, schema_editor):
    """The models that trained with a lidar on this console until now learnt Pitlane's (facing
    forwards, 0.1 m up); from here on they read simapp's (facing backwards, 0.182 m up), so
    their page says so. Imports never trained here and are left alone."""
    TrainingJob = apps.get_model("training", "TrainingJob")
    trained = TrainingJob.objects.filter(iterations__gt=0).exclude(lease_owner=IMPORTED)
    RLModel = apps.get_model("training", "RLModel")
    with_lidar = [
        model.pk
        for model in RLModel.objects.filter(pk__in=trained.values("model")).only("sensors")
        if any(sensor in LIDARS for sensor in model.sensors)
    ]
    RLModel.objects.filter(pk__in=with_lidar).update(lidar_before_deepracer=True)


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0021_world_name"),
    ]

    operations = [
        migrations.AddField(
            model_name="rlmodel",
            name="lidar_before_deepracer",
            field=models.BooleanField(
                default=False,
                editable=False,
                help_text="Trained with a lidar on this console before issue 44 put it on "
                "simapp's mount (migration 0022): it learnt a lidar facing forwards 0.1 m up, "
                "and now reads one facing backwards 0.182 m up.",
            ),
        ),
        migrations.RunPython(mark_lidar_before_deepracer, migrations.RunPython.noop),
    ]
