from django.db import migrations


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0016_evaluation_max_resets"),
    ]

    operations = []
