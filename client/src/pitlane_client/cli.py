"""``pitlane``: the console's API from a shell, with DeepRacer for Cloud's verbs.

    pitlane login --url URL --token TOKEN
    pitlane models list|show ID|stop ID|delete ID|clone ID NAME
    pitlane train FOLDER [--name NAME] [--minutes N] [--wait]     (or: models create FOLDER)
    pitlane import s3://BUCKET/PREFIX|FOLDER|ARCHIVE [--endpoint-url URL] [--yes]   (or upload)
    pitlane logs ID [--follow]
    pitlane download ID [--physical|--onnx|--virtual|--logs] [--checkpoint best|last]
    pitlane evaluate ID [--trials N] [--checkpoint best|last] [--wait]
    pitlane submit ID EVENT    pitlane leaderboard EVENT    pitlane runs

Lists are tables; ``--json`` prints what the API answered, for scripts. The URL and token come
from ``pitlane login`` (kept in ~/.config/pitlane/config.json, for its owner alone), or from
PITLANE_URL and PITLANE_TOKEN. A refusal prints the console's words and exits 1.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from pitlane_client import ApiError, Client, drfc, folder_files

WHOLE = "__all__"  # a refusal of the request as a whole, not of one input (the console's name)
WAIT_EVERY = 2.0  # [s] between looks while --wait waits
MODEL_COLUMNS = ("id", "name", "status", "track", "algorithm")
MODEL_SETTINGS = ("direction", "race_type", "network", "max_minutes", "workers", "seed",
                  "domain_randomisation", "best_checkpoint_by", "evaluation_trials",
                  "cloned_from")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        return args.run(args) or 0
    except ApiError as refusal:
        for line in _refusal_lines(refusal):
            print(f"pitlane: {line}", file=sys.stderr)
        return 1
    except (OSError, ValueError) as error:
        print(f"pitlane: {error}", file=sys.stderr)
        return 1


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="pitlane", description="Pitlane's console from a shell.")
    parser.add_argument("--json", action="store_true", help="print the API's answer as JSON")
    verbs = parser.add_subparsers(required=True, metavar="VERB")

    login = verbs.add_parser("login", help="keep the console's URL and your token")
    login.add_argument("--url", required=True)
    login.add_argument("--token", required=True, help="made on your profile page")
    login.set_defaults(run=_login)

    models = verbs.add_parser("models", help="your models").add_subparsers(required=True)
    listed = models.add_parser("list")
    listed.add_argument("--status")
    listed.add_argument("--track")
    listed.set_defaults(run=_models_list)
    for verb, run in (("show", _model_show), ("stop", _model_stop), ("delete", _model_delete)):
        one = models.add_parser(verb)
        one.add_argument("model", type=int)
        one.set_defaults(run=run)
    clone = models.add_parser("clone")
    clone.add_argument("model", type=int)
    clone.add_argument("name")
    clone.add_argument("--checkpoint", type=_checkpoint, default="best", help="best, last or N")
    clone.add_argument("--minutes", type=int)
    clone.set_defaults(run=_model_clone)

    for train in (  # `models create FOLDER` is `train FOLDER`, as DRfC's users reach for both
        verbs.add_parser("train", help="create a model from a DeepRacer for Cloud folder"),
        models.add_parser("create", help="create a model from a DeepRacer for Cloud folder"),
    ):
        train.add_argument("folder", type=Path)
        train.add_argument("--name")
        train.add_argument("--minutes", type=int)
        train.add_argument("--wait", action="store_true", help="until its first iteration")
        train.set_defaults(run=_train)

    for verb in ("import", "upload"):
        imported = verbs.add_parser(
            verb, help="import a model: s3://bucket/prefix (DeepRacer for Cloud), a folder or a tar"
        )
        imported.add_argument("source", help="s3://bucket/prefix, a model folder, or an archive")
        imported.add_argument("--name")
        imported.add_argument("--endpoint-url", help="the S3 API's, for MinIO (DRfC's default)")
        imported.add_argument("--profile", help="the AWS profile whose credentials read S3")
        imported.add_argument("--yes", action="store_true", help="confirm a preview's training")
        imported.add_argument("--minutes", type=int, help="a previewed model's training time")
        imported.set_defaults(run=_import)

    logs = verbs.add_parser("logs", help="a model's training log")
    logs.add_argument("model", type=int)
    logs.add_argument("--follow", "-f", action="store_true", help="until its training ends")
    logs.set_defaults(run=_logs)

    download = verbs.add_parser("download", help="a model's archive")
    download.add_argument("model", type=int)
    kinds = download.add_mutually_exclusive_group()
    for kind in ("physical", "onnx", "virtual", "logs"):
        kinds.add_argument(f"--{kind}", dest="kind", action="store_const", const=kind)
    download.add_argument("--checkpoint", choices=("best", "last"), default="best")
    download.add_argument("--into", type=Path, default=Path.cwd())
    download.set_defaults(run=_download, kind="physical")

    evaluate = verbs.add_parser("evaluate", help="evaluate a model")
    evaluate.add_argument("model", type=int)
    evaluate.add_argument("--trials", type=int)
    evaluate.add_argument("--checkpoint", choices=("best", "last"))
    evaluate.add_argument(
        "--max-resets", type=int, help="per trial, as DRfC's DR_EVAL_MAX_RESETS (0: ends off track)"
    )
    evaluate.add_argument("--wait", action="store_true", help="until it ends")
    evaluate.set_defaults(run=_evaluate)

    submit = verbs.add_parser("submit", help="race a model in an event")
    submit.add_argument("model", type=int)
    submit.add_argument("event", help="the event's slug, as its address has it")
    submit.add_argument("--checkpoint", choices=("best", "last"), default="best")
    submit.set_defaults(run=_submit)

    board = verbs.add_parser("leaderboard", help="an event's leaderboard")
    board.add_argument("event")
    board.add_argument("--page", type=int, default=1)
    board.set_defaults(run=_leaderboard)

    verbs.add_parser("runs", help="your race runs").set_defaults(run=_runs)
    return parser


def _checkpoint(given: str) -> str | int:
    """best, last, or an iteration's number (DeepRacer for Cloud's ``dr-upload-model -c N``)."""
    if given in ("best", "last"):
        return given
    if given.isdigit():
        return int(given)
    raise argparse.ArgumentTypeError("give best, last or an iteration's number")


# The verbs


def _config() -> Path:
    home = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config")
    return home / "pitlane" / "config.json"


def _login(args) -> int:
    client = Client(args.url, args.token)
    me = client.me()  # the token works before it is kept
    config = _config()
    config.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    config.touch(mode=0o600)
    config.write_text(json.dumps({"url": client.url, "token": args.token}))
    _say(args, me, f"Logged in to {client.url} as {me['racer_name']} ({', '.join(me['scopes'])}).")
    return 0


def _models_list(args) -> int:
    page = _client().models(status=args.status, track=args.track, limit=100)
    if args.json:
        return _print_json(page)
    _table(page["items"], MODEL_COLUMNS)
    return 0


def _model_show(args) -> int:
    model = _client().model(args.model)
    if args.json:
        return _print_json(model)
    for key in (*MODEL_COLUMNS, *MODEL_SETTINGS):
        if key in model:  # a console older than this client gives fewer
            print(f"{key:>20}  {model[key]}")
    for key, value in model["checkpoints"].items():
        print(f"{key:>20}  {value}")
    return 0


def _model_stop(args) -> int:
    stopped = _client().stop(args.model)
    return _say(args, stopped, f"{stopped['status'].capitalize()}: {stopped['message']}")


def _model_delete(args) -> int:
    deleted = _client().delete(args.model)
    return _say(args, deleted, f"Deleted model {args.model} ({deleted['files_removed']} files).")


def _model_clone(args) -> int:
    changes = {"checkpoint": args.checkpoint}
    if args.minutes:
        changes["max_minutes"] = args.minutes
    clone = _client().clone(args.model, args.name, **changes)
    return _say(args, clone, f"Created {clone['name']} (#{clone['id']}); its training is queued.")


def _train(args) -> int:
    files = folder_files(args.folder)
    fields = {"name": args.name, "max_minutes": args.minutes}
    client = _client()
    model = client.create(files, **{k: v for k, v in fields.items() if v is not None})
    if not args.json:
        print(f"Created {model['name']} (#{model['id']}); its training is queued.")
        for note in model["notes"]:
            print(f"  note: {note}")
    if args.wait:
        model["iterations"] = _wait(
            "the first iteration", lambda: client.iterations(model["id"]), bool
        )
    return _print_json(model) if args.json else 0


def _import(args) -> int:
    """A model into the console from DeepRacer for Cloud's S3 prefix, a model folder or an
    archive: at once when it brings its weights, else after its preview is confirmed."""
    client = _client()
    with tempfile.TemporaryDirectory(prefix="pitlane-") as work:
        archive = _archive_of(args, Path(work))
        bar = None if args.json else _bar(f"uploading {archive.name}")
        answer = client.import_archive(archive, args.name or "", progress=bar)
    if not args.json:
        print(file=sys.stderr)
    if "kept" in answer:
        answer = _confirmed(args, client, answer)
        if answer is None:
            return 1
    if args.json:
        return _print_json(answer)
    print(f"Imported {answer['name']} (#{answer['id']}): {answer['status'].lower()}.")
    for note in answer["notes"]:
        print(f"  note: {note}")
    return 0


def _archive_of(args, work: Path) -> Path:
    """The archive to send: ``args.source`` itself, a folder packed, or an S3 prefix read."""
    source = args.source
    if source.startswith("s3://"):
        return _from_s3(args, work / "drfc-model.tar")
    path = Path(source)
    if path.is_dir():
        packed = work / f"{path.resolve().name or 'model'}.tar.gz"
        with tarfile.open(packed, "w:gz") as tar:
            for file in sorted(p for p in path.rglob("*") if p.is_file()):
                tar.add(file, arcname=file.relative_to(path).as_posix())
        return packed
    if not path.is_file():
        raise ValueError(f"{source}: no such folder or archive")
    return path


def _from_s3(args, into: Path) -> Path:
    try:
        import boto3
        from botocore.exceptions import BotoCoreError, ClientError
    except ImportError:
        raise ValueError(
            "reading S3 needs boto3: pip install 'pitlane-client[s3]' (or boto3)"
        ) from None
    session = boto3.Session(profile_name=args.profile)
    s3 = session.client("s3", endpoint_url=args.endpoint_url)
    bar = None if args.json else _bar(f"reading {args.source}")
    try:
        with into.open("wb") as out:
            packed = drfc.pack(s3, args.source, out, progress=bar)
    except (BotoCoreError, ClientError) as error:
        raise ValueError(f"{args.source}: S3 answered: {error}") from None
    if not args.json:
        print(file=sys.stderr)
        for note in packed.notes:
            print(f"  note: {note}")
    return into


def _confirmed(args, client: Client, preview: dict) -> dict | None:
    """The previewed model created once confirmed (``--yes``, or the racer's answer)."""
    settings = preview["settings"]
    if not args.json:
        print(
            f"{settings['name']} would train on {settings['track']} ({settings['direction']}), "
            f"up to {args.minutes or settings['max_minutes']} min of your training time."
        )
        for note in preview["notes"]:
            print(f"  note: {note}")
        for setting, problem in preview["problems"].items():
            print(f"  to fix: {setting}: {problem}")
    if not args.yes and not (sys.stdin.isatty() and input("Train it? [y/N] ").lower() == "y"):
        client.import_cancel()
        print("Not imported: nothing was created.", file=sys.stderr)
        return None
    changes = {"max_minutes": args.minutes} if args.minutes else {}
    return client.import_confirm(preview["kept"], name=settings["name"], **changes)


def _logs(args) -> int:
    """The model's training log, as dr-logs-sagemaker shows the trainer's; ``--follow`` asks for
    new lines every few seconds until the training ends."""
    client = _client()
    after = 0
    while True:
        page = client.log(args.model, after=after, limit=1000)
        for line in page["lines"]:
            if args.json:
                print(json.dumps(line))
            else:
                level = "" if line["level"] == "info" else f" {line['level'].upper()}:"
                print(
                    f"{line['at'][:19].replace('T', ' ')}  [{line['source']}]{level} {line['text']}"
                )
        after = page["next"]
        if len(page["lines"]) == 1000:
            continue  # more already written
        if not (args.follow and page["active"]):
            return 0
        time.sleep(WAIT_EVERY)


def _download(args) -> int:
    bar = None if args.json else _bar(f"{args.kind} archive")
    path = _client().download(args.model, args.kind, args.into, args.checkpoint, progress=bar)
    if not args.json:
        print()
    return _say(args, {"path": str(path)}, f"Saved {path}")


def _evaluate(args) -> int:
    given = (
        ("trials", args.trials),
        ("checkpoint", args.checkpoint),
        ("max_resets", args.max_resets),
    )
    settings = {key: value for key, value in given if value is not None}
    client = _client()
    evaluation = client.evaluate(args.model, **settings)
    if args.wait:
        evaluation = _wait(
            "the evaluation",
            lambda: client.evaluation(args.model, evaluation["id"]),
            lambda got: got["status"] in ("COMPLETED", "FAILED", "CANCELED"),
        )
    if args.json:
        return _print_json(evaluation)
    print(f"Evaluation #{evaluation['id']}: {evaluation['status']}")
    _table(evaluation["results"], ("number", "time_ms", "progress", "status", "off_tracks"))
    return 0


def _submit(args) -> int:
    run = _client().submit(args.model, args.event, args.checkpoint)
    return _say(
        args, run, f"{run['model_name']} is on the grid for {args.event} (run #{run['id']})."
    )


def _leaderboard(args) -> int:
    board = _client().leaderboard(args.event, args.page)
    if args.json:
        return _print_json(board)
    _table(board["items"], ("position", "racer", "model_name", "score_ms", "gap_ms"))
    print(f"page {board['page']} of {board['pages']}, {board['count']} ranked")
    return 0


def _runs(args) -> int:
    runs = _client().runs()
    if args.json:
        return _print_json(runs)
    _table(runs, ("id", "event", "model_name", "status", "score_ms", "laps_completed"))
    return 0


# Helpers


def _refusal_lines(refusal: ApiError) -> list[str]:
    """The console's words: one line for each input at fault where it named them."""
    if not refusal.errors:
        return [str(refusal)]
    return [m if n == WHOLE else f"{n}: {m}" for n, m in refusal.errors.items()]


def _client() -> Client:
    url, token = os.environ.get("PITLANE_URL"), os.environ.get("PITLANE_TOKEN")
    if not (url and token) and _config().is_file():
        kept = json.loads(_config().read_text())
        url, token = url or kept.get("url"), token or kept.get("token")
    if not (url and token):
        raise ValueError("not logged in: run `pitlane login --url URL --token TOKEN` first")
    return Client(url, token)


def _say(args, answer, words: str) -> int:
    if args.json:
        return _print_json(answer)
    print(words)
    return 0


def _print_json(answer) -> int:
    print(json.dumps(answer, indent=2))
    return 0


def _table(rows: list[dict], columns: tuple[str, ...]) -> None:
    cells = [[str(row.get(column, "")) for column in columns] for row in rows]
    widths = [max([len(c), *(len(r[i]) for r in cells)]) for i, c in enumerate(columns)]
    for line in (list(columns), *cells):
        print("  ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True)))


def _bar(what: str):
    """A progress bar on standard error, for a download of ``what``."""

    def shown(done: int, total: int | None) -> None:
        if total:
            filled = round(30 * done / total)
            line = f"[{'#' * filled}{'.' * (30 - filled)}] {done * 100 // total}%"
        else:
            line = f"{done / 2**20:.1f} MiB"
        print(f"\r{what}: {line}", end="", file=sys.stderr, flush=True)

    return shown


def _wait(what: str, look, done) -> object:
    """``look()`` every few seconds until ``done`` of what it gives, with a spinner on standard
    error; what it gave last."""
    started = time.monotonic()
    while True:
        got = look()
        if done(got):
            print(file=sys.stderr)
            return got
        print(f"\rwaiting for {what}: {time.monotonic() - started:.0f} s", end="", file=sys.stderr)
        time.sleep(WAIT_EVERY)


if __name__ == "__main__":
    sys.exit(main())
