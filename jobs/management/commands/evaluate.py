from django.core.management.base import BaseCommand, CommandError

from common.formatting import laptime
from common.refusals import Refused
from jobs import evaluation
from simulator import config as sim
from training import services
from training.management.lookup import find_model
from training.models import EvaluationJob


class Command(BaseCommand):
    help = (
        "Evaluate a ready model in this process, as the Evaluate button does on a worker, and "
        "print the results per trial. MODEL is the model's name (with --owner when two racers "
        "use it) or its number."
    )

    def add_arguments(self, parser) -> None:
        parser.add_argument("model", help="the model's name or number")
        parser.add_argument("--owner", help="the racer who owns the model")
        parser.add_argument("--track", help="a built-in track (default: the model's own)")
        parser.add_argument("--direction", choices=["counterclockwise", "clockwise"])
        parser.add_argument(
            "--race-type",
            choices=["TIME_TRIAL", "OBJECT_AVOIDANCE", "HEAD_TO_BOT"],
            default="TIME_TRIAL",
        )
        parser.add_argument("--boxes", type=int, help="boxes, for OBJECT_AVOIDANCE")
        parser.add_argument("--bots", type=int, help="bot cars, for HEAD_TO_BOT")
        parser.add_argument("--trials", type=int, default=3, help="3 to 5 (default 3)")
        parser.add_argument("--continuous", action="store_true", help="consecutive laps")
        parser.add_argument("--off-track-penalty", type=float, default=2.0, help="[s]")
        parser.add_argument("--crash-penalty", type=float, default=5.0, help="[s]")
        parser.add_argument(
            "--max-resets",
            type=int,
            default=sim.DEFAULT_MAX_RESETS,
            help="resets a trial may use before it ends (default 100; -1: no limit)",
        )
        parser.add_argument("--checkpoint", choices=["best", "last"], default="best")
        parser.add_argument(
            "--randomise",
            action="store_true",
            help="each trial in a randomised scene (domain randomisation), whatever the model "
            "trained in",
        )
        parser.add_argument(
            "--seed",
            type=int,
            help="drive the trials of the evaluation or race entry that had this seed again, "
            "given the same options: the evaluation's, or the event's race rules, track and the "
            "entry's --checkpoint (their pages show the seed); default: a new one",
        )

    def handle(self, *args, **options) -> None:
        model = find_model(options["model"], options["owner"])
        settings = {
            "race_type": options["race_type"],
            "trials": options["trials"],
            "continuous_laps": options["continuous"],
            "off_track_penalty": options["off_track_penalty"],
            "crash_penalty": options["crash_penalty"],
            "max_resets": None if options["max_resets"] == -1 else options["max_resets"],
            "checkpoint": options["checkpoint"],
            "domain_randomisation": options["randomise"],
        }
        if options["track"]:
            settings["track"] = options["track"]
        if options["direction"]:
            settings["direction"] = options["direction"]
        if options["boxes"] is not None:
            settings["boxes"] = {"count": options["boxes"]}
        if options["bots"] is not None:
            settings["bots"] = {"count": options["bots"]}
        try:
            job = services.evaluation_start(
                model=model, settings=settings, seed=options["seed"], enqueue=False
            )
        except Refused as refused:
            raise CommandError(refused.told("The evaluation was not started")) from None
        self.stdout.write(
            f"Evaluating {model.name} on {job.track} ({job.direction}), {job.trials} trials, "
            f"seed {job.seed}{', randomised scenes' if job.domain_randomisation else ''}…"
        )
        evaluation.run(job.pk)
        job.refresh_from_db()
        if job.status != EvaluationJob.Status.COMPLETED:
            raise CommandError(f"The evaluation failed: {job.failure_reason}")
        self.stdout.write(self._table(job))

    def _table(self, job: EvaluationJob) -> str:
        header = (
            "Trial",
            "Time",
            "Completed",
            "Status",
            "Off-tracks",
            "Crashes",
            "Penalty",
            "Resets",
        )
        rows = [_row(trial) for trial in job.trial_rows.all()]
        widths = [max(len(row[i]) for row in [header, *rows]) for i in range(len(header))]
        lines = [
            "  ".join(cell.rjust(width) for cell, width in zip(row, widths, strict=True))
            for row in [header, *rows]
        ]
        lines.append(f"Video, trace and metrics: {job.video.rsplit('/', 1)[0]}/")
        return "\n".join(lines)


def _row(trial) -> tuple[str, ...]:
    return (
        str(trial.number),
        laptime(trial.time_ms),
        f"{trial.progress:.1f}%",
        trial.status,
        str(trial.off_tracks),
        str(trial.crashes),
        laptime(trial.penalty_ms),
        str(trial.resets),
    )
