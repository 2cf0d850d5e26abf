from django.db import migrations, models


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0019_trial_seeds_and_checkpoints"),
    ]

    operations = [
        migrations.AddField(
            model_name="rlmodel",
            name="domain_randomisation",
            field=models.BooleanField(
                default=False,
                help_text="Each episode in a scene of its own: light, colours, textures, camera "
                "noise and blur, a little camera, grip and motor jitter (simulator.randomisation); "
                "DeepRacer for Cloud's DR_ENABLE_DOMAIN_RANDOMIZATION.",
            ),
        ),
        migrations.AddField(
            model_name="evaluationjob",
            name="domain_randomisation",
            field=models.BooleanField(
                default=False,
                help_text="Each trial in a randomised scene, whatever the model trained in.",
            ),
        ),
    ]
