from django.db import migrations


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0019_trial_seeds_and_checkpoints"),
    ]

    operations = []
