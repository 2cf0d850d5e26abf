from django.db import migrations


class Migration(migrations.Migration):
    dependencies = [
        ("training", "0017_track_catalogue"),
    ]

    operations = []
