from pathlib import Path

from django.core.files.storage import default_storage
from django.core.management.base import BaseCommand, CommandError

from archives import exports, logs_archive
from training.management.lookup import find_model


class Command(BaseCommand):
    help = (
        "Write a model's archive: --physical for the car (model_metadata.json, and the network "
        "as DeepRacer's TensorFlow frozen graph, agent/model.pb), --onnx for custom cars and "
        "other runtimes (model_metadata.json and model.onnx), --virtual for another Pitlane or "
        "DeepRacer toolchain (settings, reward function, checkpoints, metrics), --logs for log "
        "analysis (simulation traces and metrics laid out as a DeepRacer model folder)."
    )

    def add_arguments(self, parser) -> None:
        parser.add_argument("model", help="the model's name or number")
        parser.add_argument("--owner", help="the racer who owns the model")
        kind = parser.add_mutually_exclusive_group(required=True)
        kind.add_argument("--physical", action="store_true", help="the archive for the car")
        kind.add_argument("--onnx", action="store_true", help="the network as ONNX")
        kind.add_argument("--virtual", action="store_true", help="the archive to train on")
        kind.add_argument("--logs", action="store_true", help="the logs, for log analysis")
        parser.add_argument(
            "--checkpoint",
            choices=["best", "last"],
            default="best",
            help="which checkpoint goes on the car or into ONNX (default: best)",
        )
        parser.add_argument("-o", "--output", help="where to write it (default: its own name)")

    def handle(self, *args, **options) -> None:
        model = find_model(options["model"], options["owner"])
        if options["logs"]:
            self._write_logs(model, options["output"])
            return
        try:
            if options["physical"]:
                export = exports.physical(model, options["checkpoint"])
            elif options["onnx"]:
                export = exports.onnx(model, options["checkpoint"])
            else:
                export = exports.virtual(model)
        except exports.ExportRefused as refused:
            raise CommandError(str(refused)) from None
        output = Path(options["output"] or export.filename)
        if output.is_dir():
            output = output / export.filename
        try:
            with default_storage.open(export.name, "rb") as source, output.open("wb") as target:
                while chunk := source.read(1024 * 1024):
                    target.write(chunk)
        except OSError as error:
            raise CommandError(f"Could not write {output}: {error.strerror or error}") from None
        self.stdout.write(f"Wrote {output} ({output.stat().st_size:,} bytes).")

    def _write_logs(self, model, output: str | None) -> None:
        if not logs_archive.has_logs(model):
            raise CommandError(logs_archive.NO_LOGS)
        target = Path(output or logs_archive.filename(model))
        if target.is_dir():
            target = target / logs_archive.filename(model)
        try:
            with target.open("wb") as handle:
                logs_archive.write(model, handle)
        except OSError as error:
            raise CommandError(f"Could not write {target}: {error.strerror or error}") from None
        self.stdout.write(f"Wrote {target} ({target.stat().st_size:,} bytes).")
