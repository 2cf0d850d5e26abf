"""Models trained before the networks became DeepRacer's keep theirs (layout 1); new ones get
DeepRacer's (layout 2)."""

from django.db import migrations, models


class Migration(migrations.Migration):
    dependencies = [("training", "0010_loss_type_spelled_as_deepracer")]

    operations = [
        migrations.AddField(
            model_name="rlmodel",
            name="network_layout",
            field=models.PositiveSmallIntegerField(default=1),
        ),
        migrations.AlterField(
            model_name="rlmodel",
            name="network_layout",
            field=models.PositiveSmallIntegerField(
                default=2,
                help_text="2: DeepRacer's networks, layer for layer; 1: Pitlane's own, before "
                "(its weights are for those).",
            ),
        ),
    ]
