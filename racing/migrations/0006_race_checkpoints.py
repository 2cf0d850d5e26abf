from django.db import migrations


class Migration(migrations.Migration):
    dependencies = [
        ("racing", "0005_issue41"),
    ]

    operations = []
