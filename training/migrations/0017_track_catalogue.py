from django.db import migrations, models


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0016_evaluation_max_resets"),
    ]

    operations = [
        migrations.AlterField(
            model_name="track",
            name="description",
            field=models.CharField(blank=True, max_length=500),
        ),
        migrations.AddField(
            model_name="track",
            name="default_direction",
            field=models.CharField(
                choices=[("counterclockwise", "Counter-clockwise"), ("clockwise", "Clockwise")],
                default="counterclockwise",
                help_text="The direction offered first (DeepRacer's console: defaultDirection).",
                max_length=16,
            ),
        ),
        migrations.AddField(
            model_name="track",
            name="season",
            field=models.PositiveSmallIntegerField(
                blank=True,
                help_text="The year DeepRacer raced it, as deepracer-utils' track_meta groups the "
                "tracks (2019: 2019 and earlier); empty for Pitlane's own and added tracks.",
                null=True,
            ),
        ),
    ]
