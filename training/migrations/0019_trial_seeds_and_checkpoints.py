from django.db import migrations, models

import training.models

CHECKPOINTS = [("best", "Best"), ("last", "Last")]


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0018_camera_lens"),
    ]

    operations = [
        migrations.AddField(
            model_name="rlmodel",
            name="best_checkpoint_by",
            field=models.CharField(
                choices=[
                    ("progress", "Progress (DeepRacer's)"),
                    ("reward", "Reward"),
                    ("laptime", "Lap time"),
                ],
                default="progress",
                help_text="How training picks the best checkpoint (DR_TRAIN_BEST_MODEL_METRIC).",
                max_length=8,
            ),
        ),
        migrations.AddField(
            model_name="rlmodel",
            name="cloned_checkpoint",
            field=models.CharField(
                blank=True,
                choices=CHECKPOINTS,
                help_text="A clone's start: its source's best or last checkpoint.",
                max_length=8,
            ),
        ),
        migrations.AddField(
            model_name="iteration",
            name="evaluation_reward",
            field=models.FloatField(
                blank=True, help_text="Mean total reward of the evaluation episodes.", null=True
            ),
        ),
        migrations.AddField(
            model_name="iteration",
            name="evaluation_lap_ms",
            field=models.FloatField(
                blank=True,
                help_text="[ms] mean lap time of the evaluation episodes, 999999 for each "
                "unfinished one (DeepRacer's best-model lap time).",
                null=True,
            ),
        ),
        # Evaluations made before seeds keep none: they drove without noise, and replay so.
        migrations.AddField(
            model_name="evaluationjob",
            name="seed",
            field=models.PositiveIntegerField(blank=True, null=True),
        ),
        migrations.AlterField(
            model_name="evaluationjob",
            name="seed",
            field=models.PositiveIntegerField(
                blank=True,
                default=training.models.new_seed,
                help_text="Seeds its trials' noise; the same seed drives them again exactly. "
                "Empty: driven without noise (before seeds).",
                null=True,
            ),
        ),
        # "Best" is picked by the model's best_checkpoint_by, not always by completion.
        migrations.AlterField(
            model_name="evaluationjob",
            name="checkpoint",
            field=models.CharField(choices=CHECKPOINTS, default="best", max_length=8),
        ),
        migrations.AddField(
            model_name="evaluationtrial",
            name="seed",
            field=models.PositiveIntegerField(
                blank=True, help_text="The seed of the episode it was driven in.", null=True
            ),
        ),
    ]
