from django.core.management.base import BaseCommand, CommandError

from racing.services import demo_season_load
from training.models import Track


class Command(BaseCommand):
    help = "Create the demo season and its events (safe to run again). Run loadtracks first."

    def handle(self, *args, **options) -> None:
        try:
            season = demo_season_load()
        except Track.DoesNotExist:
            raise CommandError(
                "The built-in tracks are not loaded yet; run: manage.py loadtracks"
            ) from None
        self.stdout.write(f"{season.name}: {season.events.count()} events.")
