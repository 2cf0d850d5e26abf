import json
from pathlib import Path

from django.core.management.base import BaseCommand, CommandError

from sandbox import SandboxFailure, SandboxUnavailable
from simulator import tracks
from training.rewards import reward_validate


class Command(BaseCommand):
    help = (
        "Validate a reward function against a track, as the console's Validate button does; "
        'prints JSON {"valid", "errors", "warnings", "samples", "log"} and exits 0 when valid.'
    )

    def add_arguments(self, parser) -> None:
        parser.add_argument("file", type=Path, help="the reward function's Python file")
        parser.add_argument("--track", default="rookie-loop", help="a built-in track's name")
        parser.add_argument(
            "--direction", default="counterclockwise", choices=["counterclockwise", "clockwise"]
        )

    def handle(self, *args, file: Path, track: str, direction: str, **options) -> None:
        try:
            source = file.read_text()
        except (OSError, UnicodeDecodeError) as error:
            raise CommandError(f"Cannot read {file}: {error}") from None
        try:
            tracks.load(track).with_direction(direction)
            result = reward_validate(source=source, track=track, direction=direction)
        except (tracks.TrackError, SandboxFailure, SandboxUnavailable) as error:
            raise CommandError(str(error)) from None
        self.stdout.write(json.dumps(result.as_dict(), indent=2))
        if not result.valid:
            raise CommandError(f"{len(result.errors)} error(s) in {file}.", returncode=1)
