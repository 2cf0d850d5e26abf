"""Importing a model from an archive: a Pitlane virtual model (``exports.virtual``), which arrives
READY with its weights, or a DeepRacer export, whose settings and reward function arrive as a new
model whose training is queued (its TensorFlow checkpoints cannot be loaded into our network).

An archive is hostile until proven otherwise. Before anything is written: its size, the number
of its members and their unpacked size are limited; only regular files under relative paths are
read (no absolute paths, no ``..``, no links, devices or FIFOs); the settings are checked as the
create-model page checks them, the reward function validated in the sandbox; weights are read
only from safetensors, into our own network, every tensor and shape checked. A refused archive
leaves nothing in the database or in storage.
"""

from __future__ import annotations

import json
import secrets
import tarfile
import zlib
from dataclasses import dataclass, field
from datetime import timedelta
from pathlib import PurePosixPath
from typing import IO

import yaml
from django.contrib.auth.models import AbstractBaseUser
from django.contrib.sessions.backends.base import SessionBase
from django.core.files.storage import default_storage
from django.core.files.uploadedfile import UploadedFile
from django.db import transaction
from django.utils import timezone
from safetensors import SafetensorError

from training import artifacts, configuration, exports, history, hyperparameters, jobs, services
from training.models import Algorithm, RLModel, Track, TrainingJob
from training.policies import Policy

MiB = 1024 * 1024
MAX_ARCHIVE = 256 * MiB  # [bytes] as uploaded
MAX_UNPACKED = 512 * MiB  # [bytes] all members together
MAX_MEMBERS = 256
TEXT_LIMIT = 1 * MiB  # [bytes] each of the JSON, YAML and Python files
METRICS_LIMIT = 32 * MiB  # [bytes] the training metrics: a row per episode
CHECKPOINTS = ("checkpoints/best.safetensors", "checkpoints/last.safetensors")
WANTED = {
    "model_metadata.json", "reward_function.py", "hyperparameters.json",
    "training_params.yaml", exports.PITLANE_SETTINGS, artifacts.TRAINING_METRICS, *CHECKPOINTS,
}  # fmt: skip
KEPT_FOLDER = "imports/kept"  # in storage: archives kept between a racer's attempts
KEPT_FOR = timedelta(hours=6)
KEPT_SESSION_KEY = "training:kept-import"
DEFAULT_TRACK = "rookie-loop"
DEEPRACER_ALGORITHMS = {"clipped_ppo": Algorithm.PPO, "ppo": Algorithm.PPO, "sac": Algorithm.SAC}


Members = dict[str, bytes | None]  # an archive's files: contents of those read, None for the rest


NOT_AN_ARCHIVE = (
    "This file is not a .tar.gz model archive, or it is damaged: choose the "
    "virtualmodel-<name>.tar.gz downloaded from a Pitlane model's page, or a model "
    "downloaded from DeepRacer."
)


class ImportRefused(Exception):
    """The archive cannot be imported; the message says why, in a racer's words."""


@dataclass
class Imported:
    model: RLModel
    notes: list[str] = field(default_factory=list)


def import_model(*, owner: AbstractBaseUser, archive: IO[bytes], name: str = "") -> Imported:
    """The model in ``archive`` (a file opened for reading), as ``owner``'s; ``name`` replaces
    the archive's. ``ImportRefused`` or ``configuration.Invalid`` when it cannot be imported."""
    members = read_archive(archive)
    metadata = _json(members, "model_metadata.json")
    if metadata is None:
        raise ImportRefused("The archive has no model_metadata.json: is it a model's download?")
    reward = _text(members, "reward_function.py")
    if reward is None:
        raise ImportRefused("The archive has no reward_function.py.")
    ours = _json(members, exports.PITLANE_SETTINGS) or {}
    notes: list[str] = []
    settings = _settings(metadata, ours, members, reward, name, notes)
    weights = {path: members[path] for path in CHECKPOINTS if members.get(path) is not None}
    if weights:
        imported = _import_trained(owner, settings, weights, members, ours)
        imported.notes = notes + imported.notes
        return imported
    if any(_is_tensorflow(path) for path in members):
        notes.append(
            "The archive's TensorFlow checkpoints were not carried over: this console trains "
            "PyTorch networks. The settings and the reward function were; the model trains "
            "from new weights."
        )
    model = services.model_create(owner=owner, settings=settings)
    return Imported(model, notes)


@dataclass(frozen=True)
class KeptUpload:
    """An archive the racer uploaded to a form that had to be corrected, kept in storage so that
    they need not choose it again (a browser cannot fill a file input in)."""

    token: str
    filename: str
    name: str  # in storage

    def open(self) -> IO[bytes]:
        return default_storage.open(self.name, "rb")


def upload_keep(*, session: SessionBase, upload: UploadedFile) -> KeptUpload:
    """Keep ``upload`` for the racer's next attempt (replacing one kept before); kept archives
    older than ``KEPT_FOR`` are deleted on the way, whoever left them."""
    upload_discard(session=session)
    _delete_stale_uploads()
    token = secrets.token_urlsafe(16)
    upload.seek(0)
    name = default_storage.save(f"{KEPT_FOLDER}/{token}.tar.gz", upload)
    filename = PurePosixPath(upload.name or "model.tar.gz").name[:120]
    session[KEPT_SESSION_KEY] = {"token": token, "filename": filename, "name": name}
    return KeptUpload(token, filename, name)


def upload_kept(*, session: SessionBase, token: str) -> KeptUpload | None:
    """The archive kept for this racer under ``token`` (the form's hidden field), if it still is."""
    kept = session.get(KEPT_SESSION_KEY)
    if not kept or not token or not secrets.compare_digest(kept["token"], token):
        return None
    if not default_storage.exists(kept["name"]):
        return None
    return KeptUpload(kept["token"], kept["filename"], kept["name"])


def upload_discard(*, session: SessionBase) -> None:
    """Forget, and delete, the archive kept for this racer."""
    kept = session.pop(KEPT_SESSION_KEY, None)
    if kept and default_storage.exists(kept["name"]):
        default_storage.delete(kept["name"])


def _delete_stale_uploads() -> None:
    try:
        _, names = default_storage.listdir(KEPT_FOLDER)
    except FileNotFoundError:
        return
    oldest = timezone.now() - KEPT_FOR
    for file in names:
        name = f"{KEPT_FOLDER}/{file}"
        try:
            if default_storage.get_modified_time(name) < oldest:
                default_storage.delete(name)
        except (FileNotFoundError, NotImplementedError):
            continue


def read_archive(archive: IO[bytes]) -> Members:
    """The regular files of a tar (optionally gzipped) archive by relative path, with a single
    top-level folder (as some tools pack) taken off: the contents of those an import reads
    (``WANTED``), None for the others, which are only checked; ``ImportRefused`` for anything
    unsafe."""
    archive.seek(0, 2)
    if archive.tell() > MAX_ARCHIVE:
        raise ImportRefused(f"The archive is over {size(MAX_ARCHIVE)}.")
    archive.seek(0)
    members: Members = {}
    unpacked = 0
    try:
        with tarfile.open(fileobj=archive, mode="r:*") as tar:
            for count, member in enumerate(tar, start=1):
                if count > MAX_MEMBERS:
                    raise ImportRefused(f"The archive holds over {MAX_MEMBERS} files.")
                path = _safe_path(member.name)
                if member.isdir():
                    continue
                if not member.isfile():
                    raise ImportRefused(f"{member.name} is a link or a device: models hold files.")
                unpacked += member.size
                if unpacked > MAX_UNPACKED:
                    raise ImportRefused(f"The archive unpacks to over {size(MAX_UNPACKED)}.")
                members[path] = _read(tar, member) if _wanted(path) else None
    except (tarfile.TarError, EOFError, OSError, ValueError, zlib.error):
        raise ImportRefused(NOT_AN_ARCHIVE) from None
    return _without_top_folder(members)


def _wanted(path: str) -> bool:
    """Whether an import reads ``path``, at the root or under a single top-level folder."""
    return path in WANTED or path.split("/", 1)[-1] in WANTED


def _read(tar: tarfile.TarFile, member: tarfile.TarInfo) -> bytes:
    handle = tar.extractfile(member)
    data = handle.read(member.size + 1) if handle else b""
    if len(data) != member.size:
        raise ImportRefused(f"{member.name} is cut short: the archive is damaged.")
    return data


def size(limit: int) -> str:
    return f"{limit / MiB:g} MiB" if limit >= MiB else f"{limit:,} bytes"


def _safe_path(name: str) -> str:
    path = PurePosixPath(name)
    if (
        not name
        or path.is_absolute()
        or name.startswith(("/", "\\"))
        or ".." in path.parts
        or "\\" in name
        or "\x00" in name
        or ":" in path.parts[0]
    ):
        raise ImportRefused(f"{name!r} is not a relative path inside the archive.")
    return "/".join(part for part in path.parts if part != ".")


def _without_top_folder(members: Members) -> Members:
    tops = {path.split("/", 1)[0] for path in members}
    if len(tops) == 1 and all("/" in path for path in members):
        return {path.split("/", 1)[1]: data for path, data in members.items()}
    return members


def _text(members: Members, path: str) -> str | None:
    data = members.get(path)
    if data is None:
        return None
    if len(data) > TEXT_LIMIT:
        raise ImportRefused(f"{path} is over {size(TEXT_LIMIT)}.")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ImportRefused(f"{path} is not UTF-8 text.") from None


def _json(members: Members, path: str) -> dict | None:
    text = _text(members, path)
    if text is None:
        return None
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise ImportRefused(
            f"{path} is not valid JSON (line {error.lineno}, column {error.colno})."
        ) from None
    except ValueError:
        raise ImportRefused(f"{path} is not valid JSON.") from None
    if not isinstance(document, dict):
        raise ImportRefused(f"{path} must hold a JSON object.")
    return document


def _yaml(members: Members, path: str) -> dict:
    text = _text(members, path)
    if text is None:
        return {}
    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError:
        raise ImportRefused(f"{path} is not valid YAML.") from None
    return document if isinstance(document, dict) else {}


def _settings(
    metadata: dict, ours: dict, members: Members, reward: str, name: str, notes: list[str]
) -> dict:
    """The create-model settings the archive describes, in ``training.configuration``'s
    vocabulary; what it leaves out takes the defaults, and ``notes`` says what changed."""
    params = _yaml(members, "training_params.yaml")
    algorithm = DEEPRACER_ALGORITHMS.get(
        str(metadata.get("training_algorithm", "clipped_ppo")).lower(), "unknown"
    )
    if algorithm == "unknown":
        raise ImportRefused(
            f"model_metadata.json names the algorithm {metadata.get('training_algorithm')!r}; "
            "this console trains PPO (clipped_ppo) and SAC."
        )
    given = _json(members, "hyperparameters.json") or {}
    known = hyperparameters.defaults(algorithm)
    hyper = {**known, **{key: value for key, value in given.items() if key in known}}
    track = ours.get("track") or _deepracer_track(params, notes)
    return {
        "name": name or ours.get("name") or str(params.get("CAR_NAME") or "imported-model"),
        "description": str(ours.get("description") or "Imported."),
        "track": track,
        "direction": ours.get("direction")
        or ("clockwise" if params.get("REVERSE_DIR") else "counterclockwise"),
        "race_type": ours.get("race_type") or params.get("RACE_TYPE") or "TIME_TRIAL",
        "boxes": ours.get("boxes"),
        "bots": ours.get("bots"),
        "sensors": metadata.get("sensor") or ["FRONT_FACING_CAMERA"],
        "network": metadata.get("neural_network"),
        "action_space": metadata.get("action_space"),
        "algorithm": algorithm,
        "hyperparameters": hyper,
        "max_minutes": ours.get("max_minutes", 60),
        "workers": ours.get("workers", 1),
        "extra_tracks": ours.get("extra_tracks", []),
        "seed": ours.get("seed", 0),
        "shell_colour": ours.get("shell_colour"),
        "reward_function": reward,
    }


def _deepracer_track(params: dict, notes: list[str]) -> str:
    """A DeepRacer track name (``WORLD_NAME``) as ours, or the default track (and a note)."""
    world = str(params.get("WORLD_NAME") or "")
    candidates = (world, world.lower().replace("_", "-"))
    known = Track.objects.filter(name__in=candidates).values_list("name", flat=True).first()
    if known:
        return known
    if world:
        notes.append(f"The track {world} is not one of this console's; the model trains on "
                     f"{DEFAULT_TRACK} (change it by cloning once it is ready).")  # fmt: skip
    return DEFAULT_TRACK


def _is_tensorflow(path: str) -> bool:
    name = PurePosixPath(path).name
    return ".ckpt" in name or name.endswith((".pb", ".index")) or name == "checkpoint"


def _import_trained(
    owner, settings: dict, weights: dict[str, bytes], members: Members, ours: dict
) -> Imported:
    """A Pitlane virtual model: READY, with its checkpoints, after they load into our network,
    and its training history when the archive's metrics hold one."""
    clean = configuration.check(settings, owner=owner)
    policy = Policy.for_environment(
        clean["algorithm"], clean["network"], RLModel(**clean).environment_settings()
    )
    for path, data in weights.items():
        try:
            policy.load_checkpoint(data)
        except (ValueError, RuntimeError, SafetensorError):
            raise ImportRefused(
                f"{path} does not fit the model's network: its layers differ from those the "
                "sensors, network and action space of model_metadata.json make."
            ) from None
    best = weights.get(CHECKPOINTS[0]) or weights[CHECKPOINTS[1]]
    last = weights.get(CHECKPOINTS[1]) or best
    with transaction.atomic():
        services.check_quota(owner=owner, minutes=0)
        model = RLModel.objects.create(owner=owner, status=RLModel.Status.READY, **clean)
        try:
            artifacts.write_model_files(model)
            best_name = artifacts.save(model, "checkpoints/imported-best.safetensors", best)
            last_name = artifacts.save(model, "checkpoints/imported-last.safetensors", last)
            job = TrainingJob.objects.create(
                model=model, status=TrainingJob.Status.COMPLETED, weights_version=1,
                best_checkpoint=best_name, last_checkpoint=last_name, lease_owner=jobs.IMPORTED,
                message="Imported with its weights.",
            )  # fmt: skip
            notes = _import_history(model, job, members, ours)
        except BaseException:
            artifacts.delete_all(model)
            raise
    return Imported(model, notes)


def _import_history(model: RLModel, job: TrainingJob, members: Members, ours: dict) -> list[str]:
    """The job's iterations and totals from the archive's training metrics, which are kept with
    the model; a note instead when the archive has none that can be read."""
    data = members.get(artifacts.TRAINING_METRICS)
    if data is None:
        return ["The archive has no training metrics: the model arrives without its training "
                "history (no graph or iterations)."]  # fmt: skip
    try:
        if len(data) > METRICS_LIMIT:
            raise history.Unreadable(f"it is over {size(METRICS_LIMIT)}")
        found = history.read(
            data, episodes_per_iteration=model.hyperparameters["num_episodes_between_training"]
        )
    except history.Unreadable as unreadable:
        return [f"The archive's training metrics could not be read ({unreadable}): the model "
                "arrives without its training history (no graph or iterations)."]  # fmt: skip
    seconds = ours.get("training_seconds")
    exact = isinstance(seconds, int | float) and 0 <= seconds < 10**7
    history.history_save(job=job, history=found, seconds=float(seconds) if exact else None)
    artifacts.save(model, artifacts.TRAINING_METRICS, data)
    return []
