from django.core.management.base import BaseCommand

from training.services import tracks_sync


class Command(BaseCommand):
    help = "Load the simulator's built-in tracks into the database (safe to run again)."

    def handle(self, *args, **options) -> None:
        synced = tracks_sync()
        names = ", ".join(track.display_name for track in synced)
        self.stdout.write(f"{len(synced)} built-in tracks loaded: {names}.")
