from django.db import migrations, models


class Migration(migrations.Migration):
    dependencies = [
        ("racing", "0005_issue41"),
        ("training", "0019_trial_seeds_and_checkpoints"),
    ]

    operations = [
        migrations.AddField(
            model_name="submission",
            name="checkpoint",
            field=models.CharField(
                choices=[("best", "Best"), ("last", "Last")],
                default="best",
                help_text="The model's best or last checkpoint.",
                max_length=8,
            ),
        ),
        migrations.AddField(
            model_name="submission",
            name="checkpoint_iteration",
            field=models.PositiveIntegerField(
                blank=True, help_text="The training iteration whose weights raced.", null=True
            ),
        ),
        migrations.AddField(
            model_name="submission",
            name="seed",
            field=models.PositiveIntegerField(
                blank=True,
                help_text="Its evaluation's seed: the same seed races it again.",
                null=True,
            ),
        ),
    ]
