from django.db import migrations, models


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
    ]
