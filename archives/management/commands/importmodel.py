from pathlib import Path

from django.core.management.base import BaseCommand, CommandError

from archives import drfc_bucket, imports
from common.refusals import Refused
from training.management.lookup import find_racer, redis_check


class Command(BaseCommand):
    help = (
        "Import a model from a .tar.gz archive: a Pitlane virtual model or a DeepRacer model "
        "(console or DeepRacer for Cloud export: it arrives ready, with its weights; without "
        "weights, its training is queued), or a car archive (model.pb and model_metadata.json: "
        "ready to evaluate and race, not to train); or a DeepRacer for Cloud model's prefix in "
        "S3, s3://bucket/prefix, read with PITLANE_DRFC_S3_*'s keys."
    )

    def add_arguments(self, parser) -> None:
        parser.add_argument("file", help="the archive, or s3://bucket/prefix")
        parser.add_argument("--owner", required=True, help="the racer who will own the model")
        parser.add_argument("--name", default="", help="the model's name (default: the archive's)")

    def handle(self, *args, file: str, owner: str, name: str, **options) -> None:
        racer = find_racer(owner)
        redis_check("Nothing was imported.")  # a model without weights queues its training
        try:
            if file.startswith("s3://"):
                imported = drfc_bucket.import_from_bucket(owner=racer, url=file, name=name)
            else:
                with Path(file).open("rb") as archive:
                    imported = imports.import_model(owner=racer, archive=archive, name=name)
        except OSError as error:
            raise CommandError(f"Cannot read {file}: {error.strerror or error}") from None
        except Refused as refused:
            raise CommandError(refused.told("The model was not imported")) from None
        model = imported.model
        state = "ready" if model.status == model.Status.READY else "queued for training"
        self.stdout.write(f"Imported {model.name} (#{model.pk}), {state}.")
        for note in imported.notes:
            self.stdout.write(note)
