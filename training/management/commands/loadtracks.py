from pathlib import Path

from django.core.management.base import BaseCommand, CommandError

from simulator import tracks as simulator_tracks
from training.models import Direction, Track
from training.services import TrackRefused, track_add, tracks_sync


class Command(BaseCommand):
    help = (
        "Without a file: load the simulator's built-in tracks into the database (safe to run "
        "again). With a DeepRacer route file (.npy): add it as a track racers can train, evaluate "
        "and race on, e.g. loadtracks H_track.npy --name H_track "
        '--display-name "H track" (DeepRacer\'s own tracks are built in).'
    )

    def add_arguments(self, parser) -> None:
        parser.add_argument("file", nargs="?", help="a DeepRacer route file (.npy) to add")
        parser.add_argument(
            "--name",
            help="the track's name, as a WORLD_NAME names it (letters, digits, '_' and '-'); "
            "the file's name without .npy when left out",
        )
        parser.add_argument("--display-name", default="", help="what racers see (the name)")
        parser.add_argument(
            "--directions",
            default=",".join(d.value for d in Direction),
            help="the directions racers may drive it, comma-separated "
            "(counterclockwise,clockwise: both)",
        )
        parser.add_argument("--description", default="")
        parser.add_argument(
            "--difficulty",
            default=Track.Difficulty.INTERMEDIATE,
            help=f"one of {', '.join(Track.Difficulty.values)} (intermediate)",
        )
        parser.add_argument(
            "--replace", action="store_true", help="update the added track of that name"
        )

    def handle(self, *args, **options) -> None:
        if not options["file"]:
            if options["name"] or options["replace"]:
                raise CommandError("--name and --replace go with a route file to add.")
            synced = tracks_sync()
            deepracers = set(simulator_tracks.names(origin="deepracer"))
            deepracer = sum(track.name in deepracers for track in synced)
            self.stdout.write(
                f"{len(synced)} built-in tracks loaded: {len(synced) - deepracer} of Pitlane's "
                f"and {deepracer} of DeepRacer's."
            )
            return
        path = Path(options["file"])
        try:
            route = path.read_bytes()
        except OSError as error:
            raise CommandError(f"Cannot read {path}: {error.strerror or error}.") from None
        name = options["name"] or path.stem
        directions = [d.strip() for d in options["directions"].split(",") if d.strip()]
        try:
            track = track_add(
                name=name,
                display_name=options["display_name"] or name,
                route=route,
                directions=directions,
                description=options["description"],
                difficulty=options["difficulty"],
                replace=options["replace"],
            )
        except TrackRefused as error:
            raise CommandError(f"{path.name}: {error.message}") from None
        self.stdout.write(
            f"{'Replaced' if options['replace'] else 'Added'} {track.display_name} ({track.name}): "
            f"{track.length_m:.2f} m long, {track.width_m:.2f} m wide, driven "
            f"{' and '.join(track.directions).lower()}."
        )
