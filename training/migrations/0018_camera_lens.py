from django.db import migrations, models

IMPORTED = "import"  # training.leases.IMPORTED: an import's record of a job that never ran here


def mark_camera_before_deepracer(apps, schema_editor):
    """The models that trained on this console until now learnt Pitlane's camera (120°, 25°
    down); from here on they drive with DeepRacer's, so their page says so. Imports never
    trained here and are left alone."""
    TrainingJob = apps.get_model("training", "TrainingJob")
    trained = TrainingJob.objects.filter(iterations__gt=0).exclude(lease_owner=IMPORTED)
    RLModel = apps.get_model("training", "RLModel")
    RLModel.objects.filter(pk__in=trained.values("model")).update(camera_before_deepracer=True)


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0017_track_catalogue"),
    ]

    operations = [
        migrations.AddField(
            model_name="rlmodel",
            name="camera_lens",
            field=models.CharField(
                choices=[
                    ("simulator", "DeepRacer's simulated camera (64.7°)"),
                    ("wide", "The physical car's wide lens (120°)"),
                ],
                default="simulator",
                help_text="DeepRacer's simulated camera, as its console trained with, or the "
                "physical car's wide lens, for a model meant for a car.",
                max_length=10,
            ),
        ),
        migrations.AddField(
            model_name="rlmodel",
            name="camera_before_deepracer",
            field=models.BooleanField(
                default=False,
                editable=False,
                help_text="Trained on this console before issue 44 gave the car DeepRacer's "
                "camera (migration 0018): it learnt Pitlane's 120°, 25° down view, and now "
                "drives with the 64.7° one.",
            ),
        ),
        migrations.RunPython(mark_camera_before_deepracer, migrations.RunPython.noop),
    ]
