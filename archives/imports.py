"""Importing a model from an archive: a Pitlane virtual model (``exports.virtual``), or a DeepRacer
model as the DeepRacer console or DeepRacer for Cloud exports one. Either arrives READY with its
weights: ours from safetensors, DeepRacer's from its TensorFlow checkpoint (``tfcheckpoint``) or,
failing one, its frozen graph (``tfgraph``), into the same network (``tfweights``). A DeepRacer
archive without weights arrives with its settings and reward function, its training queued. A
car archive (``model.pb`` and model_metadata.json, no reward function) arrives as a model to
evaluate, race and download, which cannot train.

An archive is hostile until proven otherwise. Before anything is written: its size, the number
of its members and their unpacked size are limited; only regular files under relative paths are
read (no absolute paths, no ``..``, no links, devices or FIFOs); the settings are checked as the
create-model page checks them, the reward function validated in the sandbox; weights are read
only from safetensors or TensorFlow's formats, never unpickled or executed, into our own network,
every tensor and shape checked. A refused archive leaves nothing in the database or in storage.

DeepRacer's settings are mapped in ``archives.deepracer_settings``, an archive's files read as
text, JSON and YAML in ``archives.members``, the weights' formats in their own modules.

Long because an import is one piece read together: the archive's hostile-input checks, the
preview, the weights found and checked, the history, and the undo that leaves nothing behind a
refused import. The upload kept for a preview's confirmation is ``archives.kept_uploads``.
"""

from __future__ import annotations

import heapq
import logging
import re
import tarfile
import zlib
from dataclasses import dataclass, field
from datetime import timedelta
from pathlib import PurePosixPath
from typing import IO, TYPE_CHECKING

from django.contrib.auth.models import AbstractBaseUser
from django.db import transaction
from django.utils import timezone
from google.protobuf.message import DecodeError
from safetensors import SafetensorError

from archives import exports, history
from common import ratelimits
from rl import hyperparameters, tfcheckpoint, tfgraph
from training import artifacts, checkers, configuration, leases, lifecycle, rewards, services
from training.models import (
    CameraLens,
    Network,
    RLModel,
    Track,
    TrainingJob,
)

if TYPE_CHECKING:
    from rl.policies import Policy

from archives.deepracer_settings import SENSOR_ALIASES, archive_settings, is_route_note, shown
from archives.members import (
    NOT_AN_ARCHIVE,
    PLACES,
    ImportRefused,
    Members,
    member_json,
    member_place,
    member_text,
)

logger = logging.getLogger(__name__)

MiB = 1024 * 1024
MAX_ARCHIVE = 256 * MiB  # [bytes] as uploaded
MAX_UNPACKED = 512 * MiB  # [bytes] all members together
MAX_MEMBERS = 2048  # a virtual model's archive carries up to exports.MAX_TRACES traces
MAX_NAME = 4096  # [characters] a member's path
MAX_HEADER = 64 * 1024  # [bytes] one pax or GNU long-name header: a long name, a few attributes
MAX_HEADERS = 1 * MiB  # [bytes] all of an archive's pax and long-name headers together
EXTENDED = (
    tarfile.XHDTYPE,
    tarfile.XGLTYPE,
    tarfile.SOLARIS_XHDTYPE,
    tarfile.GNUTYPE_LONGNAME,
    tarfile.GNUTYPE_LONGLINK,
)
# [bytes] the most each file an import reads may hold (``_limit``), checked from the member's
# header before a byte of it is read; a 500 MiB reward function packs into 511 KB of gzip.
TEXT_LIMIT = 1 * MiB  # the reward function
SETTINGS_LIMIT = 256 * 1024  # model_metadata.json, hyperparameters, training_params.yaml, ...
METRICS_LIMIT = 32 * MiB  # the training metrics (a row per episode) and Pitlane's history
# A checkpoint, a TensorFlow index or a frozen graph: Pitlane's 5-layer PPO checkpoint is 219 MiB
# (the policy's and the value's networks; the 3-layer one 45 MiB, 3-layer SAC 70 MiB).
WEIGHTS_LIMIT = 256 * MiB
# [bytes] all the files an import reads together, traces aside: a best and a last checkpoint.
MAX_READ = 2 * WEIGHTS_LIMIT
# Over its limit, a file of the training history is left unread with a note; any other, refused.
HISTORY_FILES = (artifacts.TRAINING_METRICS, history.EXACT)
CHECKPOINTS = tuple(artifacts.EXPORTED_CHECKPOINTS.values())  # best, last
WANTED = {
    *(path for paths in PLACES.values() for path in paths),
    exports.PITLANE_SETTINGS,
    artifacts.TRAINING_METRICS,
    *CHECKPOINTS,
    history.EXACT,
}
# Simulation traces as DeepRacer lays them out (logs_archive), at the root or in a single folder:
# a training iteration's are read, up to exports.TRACES_LIMIT together; an evaluation's are not.
TRAINING_TRACE = re.compile(r"(?:[^/]+/)?training-simtrace/(\d{1,6})-iteration\.csv")
EVALUATION_TRACE = re.compile(r"(?:[^/]+/)?evaluation-\d{14}/evaluation-simtrace/0-iteration\.csv")
# DeepRacer's checkpoint pointers, in the folder of its checkpoints, most telling first: best and
# last by name (simapp checkpoint_files/deepracer_checkpoint_json.py:83-131), rl_coach's latest
# (rl_coach_checkpoint.py:160-179), TensorFlow's latest ("model_checkpoint_path: ...").
DEEPRACER_CHECKPOINTS, TF_CHECKPOINT = "deepracer_checkpoints.json", "checkpoint"
COACH_CHECKPOINTS = (".coach_checkpoint", "coach_checkpoint")  # the second as racers copy it
STEP = re.compile(r"(\d+)_Step-\d+\.ckpt$")  # rl_coach's checkpoint names: <N>_Step-<steps>.ckpt
GRAPH = re.compile(r"model_(\d+)\.pb$")  # simapp's frozen graph of checkpoint N
CAR_GRAPH = "agent/model.pb"  # the car archive's (exports.physical)


@dataclass
class Imported:
    model: RLModel
    notes: list[str] = field(default_factory=list)


# What the racer may change on an import's preview, and the problems of theirs it can show (the
# others are the archive's: the import is refused with them).
PREVIEW_CHANGES = ("name", "track", "direction", "max_minutes")
PREVIEW_PROBLEMS = {*PREVIEW_CHANGES, "quota"}


@dataclass
class ImportPreview:
    """What importing an archive without weights would create: a model that trains from new
    weights, using the racer's training time. Nothing is created until the racer confirms it
    (``import_start(confirmed=True)``), with the name, track, direction and training time they
    may change (``PREVIEW_CHANGES``). ``settings`` are the archive's, its hyperparameters complete;
    ``problems``: those settings' problems the racer can fix here, by setting."""

    settings: configuration.Draft
    notes: list[str]
    problems: dict[str, str] = field(default_factory=dict)

    @property
    def route(self) -> str:
        """The note on the route file the model drives, where it drives the one DeepRacer drove
        rather than the console's (``settings["world_name"]``): carried over, and used."""
        return next((note for note in self.notes if is_route_note(note)), "")

    @property
    def left_out(self) -> list[str]:
        """The notes on what the archive held that was not carried over (or was changed)."""
        return [note for note in self.notes if not is_route_note(note)]

    @property
    def track(self) -> Track | None:
        return Track.objects.filter(name=self.settings.get("track")).first()

    @property
    def direction(self) -> str:
        return configuration.direction_words(self.settings["direction"])

    @property
    def model(self) -> RLModel:
        """The model the import would create, unsaved: for the model page's includes
        (training/includes/model_race.html, model_car.html, model_action_space.html)."""
        settings = self.settings
        space = settings["action_space"]
        return RLModel(
            name=settings["name"],
            race_type=settings["race_type"],
            boxes=settings.get("boxes"),
            bots=settings.get("bots"),
            sensors=settings["sensors"],
            network=settings["network"],
            action_space_type="discrete" if isinstance(space, list) else "continuous",
            action_space=space,
            algorithm=settings["algorithm"],
            workers=settings["workers"],
            camera_lens=settings.get("camera_lens") or CameraLens.SIMULATOR,
        )


@dataclass
class _Plan:
    """What an archive holds, read and mapped to settings, before anything is written."""

    members: Members
    metadata: dict
    ours: dict
    settings: configuration.Draft
    notes: list[str]
    track_notes: list[str]  # those of ``notes`` that say which track it trains on, and why
    weights: dict[str, bytes]
    tensorflow: _TensorFlowFiles | None
    fits: bool  # DeepRacer's TensorFlow weights fit the model's network

    @property
    def reward(self) -> str:
        return self.settings["reward_function"]

    @property
    def trains(self) -> bool:
        """Whether the import makes a model that trains from new weights (none it can drive
        with came in the archive)."""
        return not self.weights and not (self.tensorflow and self.fits)


def import_model(*, owner: AbstractBaseUser, archive: IO[bytes], name: str = "") -> Imported:
    """The model in ``archive`` (a file opened for reading), as ``owner``'s, at once (its training
    queued when the archive has no weights: ``manage.py importmodel``); ``name`` replaces the
    archive's. ``ImportRefused`` or ``configuration.Invalid`` when it cannot be imported."""
    plan = _plan(archive, name)
    if plan.trains:
        model = services.model_create(owner=owner, settings=plan.settings)
        return _noted(Imported(model, plan.notes))
    return _import_ready(owner, archive, plan)


def import_start(
    *,
    owner: AbstractBaseUser,
    archive: IO[bytes],
    name: str = "",
    changes: dict | None = None,
    confirmed: bool = False,
) -> Imported | ImportPreview:
    """The import page's step: a model that arrives with its weights (READY, nothing to train)
    is imported at once, as DeepRacer's console imported one. An archive without weights would
    start a training: its ``ImportPreview`` first, and the model (with its training queued) only
    once ``confirmed`` with no problem left; ``changes``: the racer's ``PREVIEW_CHANGES``,
    checked as the create-model page checks them. ``ImportRefused`` or ``configuration.Invalid``
    for what the archive itself gets wrong."""
    plan = _plan(archive, name)
    if not plan.trains:
        return _import_ready(owner, archive, plan)
    settings = {
        **plan.settings,
        **{key: value for key, value in (changes or {}).items() if key in PREVIEW_CHANGES},
    }
    notes = _track_notes(plan, settings)
    if notes != plan.notes:  # the racer chose the track: the route the console drives it
        settings["world_name"] = ""
    where = configuration.reward_sample_track(settings)
    validation = (
        rewards.reward_validate(source=plan.reward, track=where[0], direction=where[1])
        if where
        else None
    )
    problems = _preview_problems(owner, settings, validation, track_changed=notes != plan.notes)
    if problems or not confirmed:
        settings["hyperparameters"] = hyperparameters.check(
            settings["algorithm"], settings["hyperparameters"]
        )[0]
        return ImportPreview(settings, notes, problems)
    model = services.model_create(owner=owner, settings=settings, validation=validation)
    return _noted(Imported(model, notes))


def attempt_counted(held: ratelimits.Held, outcome: object) -> None:
    """Count a posted import, held against both of the racer's import limits, against one: one
    that arrived against "import"; any other attempt (refused, or a preview to confirm) against
    the looser "import-refused", so that correcting an archive does not use up the hour's
    imports; a check that could not run counts against neither."""
    if isinstance(outcome, Imported):
        held.give_back("import-refused")
    elif isinstance(outcome, checkers.FAILURES):
        held.give_back("import", "import-refused")
    else:
        held.give_back("import")


def _plan(archive: IO[bytes], name: str) -> _Plan:
    members = read_archive(archive)
    metadata = member_json(members, member_place(members, "model_metadata.json"))
    if metadata is None:
        raise ImportRefused("The archive has no model_metadata.json: is it a model's download?")
    reward = member_text(members, member_place(members, "reward_function.py")) or ""
    ours = member_json(members, exports.PITLANE_SETTINGS) or {}
    weights = {path: members[path] for path in CHECKPOINTS if members.get(path) is not None}
    tensorflow = _TensorFlowFiles.find(members)
    if not reward.strip() and not weights and not tensorflow:
        raise ImportRefused(
            "The archive has no reward_function.py, and no weights to evaluate the model with: "
            "choose a model's download (with its reward function), or a car archive with its "
            "model.pb."
        )
    notes: list[str] = []
    track_notes: list[str] = []
    settings = archive_settings(metadata, ours, members, reward, name, notes, track_notes)
    fits = bool(not weights and tensorflow and _weights_fit(metadata, settings, notes))
    plan = _Plan(members, metadata, ours, settings, notes, track_notes, weights, tensorflow, fits)
    if plan.trains and not reward.strip():
        raise ImportRefused(
            "The archive has no reward_function.py, and its weights are for a car this console "
            "does not have (see model_metadata.json): there is nothing to train or to drive."
        )
    return plan


def _import_ready(owner: AbstractBaseUser, archive: IO[bytes], plan: _Plan) -> Imported:
    """A READY model with the archive's weights: ours (safetensors) or DeepRacer's."""
    notes = plan.notes
    if plan.weights:
        layout = plan.ours.get("network_layout", 1)  # format 1 came before DeepRacer's networks
        if layout not in (1, 2):
            raise ImportRefused(
                f"{exports.PITLANE_SETTINGS} names a network layout this console does not know "
                f"({shown(layout)}): it was exported by a newer Pitlane."
            )
        imported = _import_trained(
            owner,
            plan.settings,
            plan.members,
            plan.ours,
            layout=layout,
            checkpoints=lambda _: plan.weights,
        )
    else:  # DeepRacer's checkpoints, or a frozen graph: also our own export's, since layout 2
        tensorflow = plan.tensorflow
        told = [] if plan.ours else notes  # where they came from, unless from a Pitlane
        imported = _import_trained(
            owner,
            plan.settings,
            plan.members,
            plan.ours,
            layout=hyperparameters.NETWORK_LAYOUT,
            checkpoints=lambda policy: tensorflow.load(archive, plan.members, policy, told),
        )
    imported.notes = notes + imported.notes
    if not plan.reward.strip():
        untold = (
            ""
            if member_place(plan.members, "hyperparameters.json") in plan.members
            else (", no hyperparameters")
        )
        imported.notes.append(
            "A car archive: a driving model without training history. It can be evaluated, raced "
            "and downloaded, but not trained on or cloned: the archive brings the policy alone "
            f"(no reward function{untold}, no critics, no training time or episodes)."
        )
    return _noted(imported)


def _noted(imported: Imported) -> Imported:
    """``imported``, its notes kept with the model for its page (after any stored on the way)."""
    model = imported.model
    stored = RLModel.objects.filter(pk=model.pk).values_list("import_notes", flat=True).first()
    kept = list(stored or [])
    kept += [note for note in imported.notes if note not in kept]
    RLModel.objects.filter(pk=model.pk).update(import_notes=kept)
    model.import_notes = kept
    return imported


def _track_notes(plan: _Plan, settings: configuration.Draft) -> list[str]:
    """The plan's notes, where the racer chose another track or direction on the preview: the
    archive's track notes say only what was not carried over, and a note says what they chose."""
    if (settings["track"], settings["direction"]) == (
        plan.settings["track"],
        plan.settings["direction"],
    ):
        return list(plan.notes)
    notes = [note for note in plan.notes if note not in plan.track_notes]
    notes += [
        note.split(". ", 1)[0] + "."
        for note in plan.track_notes
        if note.startswith("Not carried over")
    ]
    track = Track.objects.filter(name=settings["track"]).first()
    shown = track.display_name if track else settings["track"]
    notes.append(
        f"You chose the track on the import's preview: {shown}, "
        f"{configuration.direction_words(settings['direction'])}."
    )
    return notes


def _preview_problems(
    owner: AbstractBaseUser,
    settings: configuration.Draft,
    validation: rewards.Validation | None,
    *,
    track_changed: bool,
) -> dict[str, str]:
    """The problems of ``settings`` the racer can fix on the preview (``PREVIEW_PROBLEMS``, and
    the reward function's on a track they chose); ``configuration.Invalid`` for the others,
    which are the archive's. The quota is read as the create-model page's save reads it."""
    fixable = PREVIEW_PROBLEMS | ({"reward_function"} if track_changed else set())
    try:
        checked = configuration.check(settings, owner=owner, validation=validation)
    except configuration.Invalid as invalid:
        if not set(invalid.errors) <= fixable:
            raise
        return dict(invalid.errors)
    try:
        with transaction.atomic():
            services.check_quota(owner=owner, minutes=checked.max_minutes)
    except configuration.Invalid as invalid:
        return dict(invalid.errors)
    return {}


def read_archive(archive: IO[bytes]) -> Members:
    """The regular files of a tar (optionally gzipped) archive by relative path, with a single
    top-level folder (as some tools pack) taken off: the contents of those an import reads
    (``WANTED``), None for the others, which are only checked; ``ImportRefused`` for anything
    unsafe."""
    archive.seek(0, 2)
    if archive.tell() > MAX_ARCHIVE:
        raise ImportRefused(f"The archive is over {size(MAX_ARCHIVE)}.")
    archive.seek(0)
    members = Members()
    unpacked = held = 0
    over: set[str] = set()
    traces = _NewestTraces()
    try:
        with tarfile.open(fileobj=archive, mode="r:*", tarinfo=_BoundedTarInfo) as tar:
            for count, member in enumerate(tar, start=1):
                if count > MAX_MEMBERS:
                    raise ImportRefused(f"The archive holds over {MAX_MEMBERS} files.")
                if len(member.name) > MAX_NAME:
                    raise ImportRefused(
                        f"A file in the archive has a name of {len(member.name):,} characters; "
                        f"the limit is {MAX_NAME:,}."
                    )
                path = _safe_path(member.name)
                if member.isdir():
                    continue
                if not member.isfile():
                    raise ImportRefused(
                        f"{member.name!r} is a link or a device: models hold files."
                    )
                if not path:
                    raise ImportRefused(f"{member.name!r} is a file without a name.")
                unpacked += member.size
                if unpacked > MAX_UNPACKED:
                    raise ImportRefused(f"The archive unpacks to over {size(MAX_UNPACKED)}.")
                if trace := TRAINING_TRACE.fullmatch(path):  # one past the limit: a note
                    kept, dropped = traces.offer(path, int(trace[1]), member.size)
                    members.update(dict.fromkeys(dropped))
                    members[path] = _read(tar, member, exports.TRACES_LIMIT) if kept else None
                    continue
                members[path] = None
                if not _wanted(path):
                    continue
                limit = _limit(path)
                if member.size > limit and _unprefixed(path) & set(HISTORY_FILES):
                    over.add(path)
                    continue
                if member.size > limit:
                    raise ImportRefused(f"{path} is over {size(limit)}.")
                held += member.size
                if held > MAX_READ:
                    raise ImportRefused(
                        f"The model's files in the archive (its settings, weights and metrics) "
                        f"are over {size(MAX_READ)} together."
                    )
                members[path] = _read(tar, member, limit)
    except (tarfile.TarError, EOFError, OSError, ValueError, zlib.error, RecursionError):
        raise ImportRefused(NOT_AN_ARCHIVE) from None
    members.over = frozenset(over)
    return _without_top_folder(members)


class _NewestTraces:
    """The training traces an import keeps, chosen as the archive is read, whatever its order:
    the newest iterations' (by number), as many as fit in ``exports.TRACES_LIMIT`` together."""

    def __init__(self) -> None:
        self.kept: list[tuple[int, str, int]] = []  # a heap: (iteration, path, size), oldest first
        self.size = 0  # [bytes] of those kept

    def offer(self, path: str, number: int, size: int) -> tuple[bool, list[str]]:
        """Whether the trace at ``path`` is kept, and the paths of those kept before that now
        make room for it."""
        heapq.heappush(self.kept, (number, path, size))
        self.size += size
        dropped = []
        while self.size > exports.TRACES_LIMIT:
            _, oldest, freed = heapq.heappop(self.kept)
            self.size -= freed
            dropped.append(oldest)
        if path in dropped:
            dropped.remove(path)
            return False, dropped
        return True, dropped


class _BoundedTarInfo(tarfile.TarInfo):
    """tarfile's member header, which refuses a pax or GNU long-name header over ``MAX_HEADER``
    bytes, or over ``MAX_HEADERS`` with those before it, before tarfile reads it into memory: it
    reads each whole, and they are not members, so their size escapes ``MAX_UNPACKED``."""

    def _proc_member(self, tar: tarfile.TarFile):
        if self.type in EXTENDED:
            tar.extended_bytes = getattr(tar, "extended_bytes", 0) + self.size
            if self.size > MAX_HEADER or tar.extended_bytes > MAX_HEADERS:
                raise ImportRefused(
                    "The archive has a long-name or extended header over "
                    f"{size(MAX_HEADER if self.size > MAX_HEADER else MAX_HEADERS)}: "
                    "model archives hold files with ordinary names."
                )
        return super()._proc_member(tar)


def _wanted(path: str) -> bool:
    """Whether an import reads ``path``, at the root or under a single top-level folder: ours,
    or DeepRacer's checkpoint indexes, pointers and frozen graphs (their checkpoints' data is read
    later, only the tensors wanted)."""
    name = PurePosixPath(path).name
    return (
        bool(_unprefixed(path) & WANTED)
        or name.endswith((tfcheckpoint.SUFFIX_INDEX, ".pb"))
        or name in (DEEPRACER_CHECKPOINTS, TF_CHECKPOINT, *COACH_CHECKPOINTS)
    )


def _limit(path: str) -> int:
    """[bytes] the most the file at ``path``, one an import reads, may hold."""
    name = PurePosixPath(path).name
    if _unprefixed(path) & set(HISTORY_FILES):
        return METRICS_LIMIT
    if name == "reward_function.py":
        return TEXT_LIMIT
    if name.endswith((".safetensors", tfcheckpoint.SUFFIX_INDEX, ".pb")):
        return WEIGHTS_LIMIT
    return SETTINGS_LIMIT


def _unprefixed(path: str) -> set[str]:
    """What ``path`` may be once a single top-level folder is taken off: itself, or the rest."""
    return {path, path.split("/", 1)[-1]}


def _read(tar: tarfile.TarFile, member: tarfile.TarInfo, limit: int) -> bytes:
    """``member``'s bytes, never more than ``limit`` + 1 of them whatever its header says."""
    handle = tar.extractfile(member)
    data = handle.read(min(member.size, limit) + 1) if handle else b""
    if len(data) > limit:
        raise ImportRefused(f"{member.name} is over {size(limit)}.")
    if len(data) != member.size:
        raise ImportRefused(f"{member.name} is cut short: the archive is damaged.")
    return data


def size(limit: int) -> str:
    return f"{limit / MiB:g} MiB" if limit >= MiB else f"{limit:,} bytes"


def _safe_path(name: str) -> str:
    """``name`` as a relative path inside the archive, its ``.`` parts taken off: '' for the
    archive's own folder (``./``, as ``tar -C folder .`` packs it), which only a folder may be;
    ``ImportRefused`` for a name that is empty, absolute, climbs out (``..``) or is written for
    another system (backslashes, a drive, NUL)."""
    path = PurePosixPath(name)
    if (
        not name
        or path.is_absolute()
        or name.startswith(("/", "\\"))
        or ".." in path.parts
        or "\\" in name
        or "\x00" in name
        or any(":" in part for part in path.parts[:1])
    ):
        raise ImportRefused(f"{name!r} is not a relative path inside the archive.")
    return "/".join(path.parts)  # PurePosixPath leaves out "." and empty parts


def _without_top_folder(members: Members) -> Members:
    tops = {path.split("/", 1)[0] for path in members}
    if len(tops) == 1 and all("/" in path for path in members):
        stripped = Members({path.split("/", 1)[1]: data for path, data in members.items()})
        stripped.top = tops.pop()
        stripped.over = frozenset(path.split("/", 1)[1] for path in members.over)
        return stripped
    return members


def _weights_fit(metadata: dict, settings: configuration.Draft, notes: list[str]) -> bool:
    """Whether DeepRacer's weights can be carried: the model has every sensor and the network
    model_metadata.json names (else a note says why they stay behind)."""
    given = metadata.get("sensor") or ["FRONT_FACING_CAMERA"]
    given = sorted(SENSOR_ALIASES.get(sensor, sensor) for sensor in given)
    network = metadata.get("neural_network") or Network.SHALLOW
    if given == sorted(settings["sensors"]) and network == settings["network"]:
        return True
    notes.append(
        "The archive's TensorFlow weights were not carried over: they are for sensors or a "
        "network this console does not have (see above). The model trains from new weights."
    )
    return False


@dataclass
class _TensorFlowFiles:
    """A DeepRacer model's weights in an archive: its checkpoints (path prefixes ``<N>_Step-<M>
    .ckpt``, best then last) and its frozen graph (the policy alone)."""

    checkpoints: list[str]
    graph: str | None

    @classmethod
    def find(cls, members: Members) -> _TensorFlowFiles | None:
        prefixes = sorted(
            path.removesuffix(tfcheckpoint.SUFFIX_INDEX)
            for path in members
            if path.endswith(tfcheckpoint.SUFFIX_INDEX)
            and path.removesuffix(tfcheckpoint.SUFFIX_INDEX) + tfcheckpoint.SUFFIX_DATA in members
        )
        checkpoints = _chosen_checkpoints(members, prefixes)
        graphs = sorted(path for path in members if path.endswith(".pb"))
        if not checkpoints and not graphs:
            return None
        best = STEP.search(checkpoints[0]) if checkpoints else None
        same = next((g for g in graphs if best and _numbered(GRAPH, g) == int(best[1])), None)
        newest = max(graphs, key=lambda g: (g == CAR_GRAPH, _numbered(GRAPH, g)), default=None)
        return cls(checkpoints, same or newest)

    def load(
        self, archive: IO[bytes], members: Members, policy: Policy, notes: list[str]
    ) -> dict[str, bytes]:
        """Our checkpoints (best, last) from the TensorFlow files, loaded into ``policy``: the
        checkpoints' policy with its critics, or, without a checkpoint, the frozen graph's
        policy."""
        from rl import tfweights

        ours = {}
        for path, prefix in zip(CHECKPOINTS, self.checkpoints or [None], strict=False):
            what = prefix or self.graph
            try:
                if prefix is None:
                    graph = tfgraph.constants(members[self.graph] or b"")
                    tfweights.load(policy, graph, complete=False)
                else:
                    tensors = _checkpoint_tensors(archive, members, prefix, policy.ppo)
                    tfweights.load(policy, tensors, complete=True)
            except (tfcheckpoint.Unreadable, tfweights.Unfit, DecodeError, ValueError) as error:
                raise ImportRefused(
                    f"{what} cannot be read into the model's network: {error}. Its layers must "
                    "be those the sensors, network and action space of model_metadata.json make."
                ) from None
            ours[path] = policy.checkpoint()
        if self.checkpoints:
            notes.append(
                f"The weights are DeepRacer's, from {', '.join(dict.fromkeys(self.checkpoints))}."
            )
        else:
            critics = "the value network" if policy.ppo else "the Q networks"
            notes.append(
                f"The policy's weights are DeepRacer's, from {self.graph}. A frozen graph holds "
                f"the policy's choice alone: its exploration spread and {critics} start from new "
                "weights if the model trains on."
            )
        return ours


def _chosen_checkpoints(members: Members, prefixes: list[str]) -> list[str]:
    """Of the checkpoints there are, the best and the last as DeepRacer's pointers name them
    (one when they are the same); the one of the highest number when none names one."""
    there = set(prefixes)
    for folder in sorted({str(PurePosixPath(p).parent) for p in prefixes}):
        at = "" if folder == "." else f"{folder}/"
        chosen = member_json(members, at + DEEPRACER_CHECKPOINTS) or {}
        names = [
            (chosen.get(key) or {}).get("name") if isinstance(chosen.get(key), dict) else None
            for key in ("best_checkpoint", "last_checkpoint")
        ]
        names += [(member_text(members, at + coach) or "").strip() for coach in COACH_CHECKPOINTS]
        latest = re.search(
            r'model_checkpoint_path:\s*"([^"]+)"', member_text(members, at + TF_CHECKPOINT) or ""
        )
        names.append(latest and PurePosixPath(latest[1]).name)
        pointed = [at + name for name in names if isinstance(name, str) and at + name in there]
        if pointed:
            last = at + str(names[1])
            return list(dict.fromkeys([pointed[0], last if last in there else pointed[0]]))
    if not prefixes:
        return []
    return [max(prefixes, key=lambda p: (_numbered(STEP, p), p))]


def _numbered(pattern: re.Pattern, path: str) -> int:
    """The number ``pattern`` captures in ``path`` (a step, a graph's); -1 where none."""
    match = pattern.search(path)
    return int(match[1]) if match else -1


def _checkpoint_tensors(archive: IO[bytes], members: Members, prefix: str, ppo: bool) -> dict:
    """The tensors ``tfweights`` reads, from the checkpoint at ``prefix``: its index lists them,
    then only their bytes are read from its data file, in one forward pass over the archive."""
    from rl import tfweights

    listed = tfcheckpoint.entries(members[prefix + tfcheckpoint.SUFFIX_INDEX] or b"")
    names = tfweights.wanted(listed, ppo)
    data_path = prefix + tfcheckpoint.SUFFIX_DATA
    archive.seek(0)
    with tarfile.open(fileobj=archive, mode="r:*") as tar:
        for member in tar:
            path = _safe_path(member.name)
            if members.top:
                path = path.removeprefix(f"{members.top}/")
            if member.isfile() and path == data_path:
                return tfcheckpoint.read(listed, names, _ranges(tar, member))
    raise ImportRefused(f"{data_path} is missing from the archive.")


def _ranges(tar: tarfile.TarFile, member: tarfile.TarInfo):
    """``data(offset, size)``: that many bytes of ``member`` from ``offset``; none past its end."""
    handle = tar.extractfile(member)

    def data(offset: int, size: int) -> bytes:
        if handle is None or offset + size > member.size:
            return b""
        handle.seek(offset)
        return handle.read(size)

    return data


def _import_trained(
    owner, settings: configuration.Draft, members: Members, ours: dict, *, layout: int, checkpoints
) -> Imported:
    """A READY model with its weights: ``checkpoints(policy)`` gives them ({path in
    ``CHECKPOINTS``: safetensors}) for the model's ``policy``, and each is checked to load into
    it; its training history comes too when the archive's metrics hold one."""
    trainable = bool(settings["reward_function"].strip())
    checked = configuration.check(settings, owner=owner, reward_required=trainable)
    checked = checked.replace(network_layout=layout)
    model = RLModel(**checked.row())
    from rl.policies import Policy  # torch: loaded by a process's first import of weights

    policy = Policy.for_environment(
        checked.algorithm, model.architecture, model.environment_settings()
    )
    weights = checkpoints(policy)
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
        model = services.model_insert(
            owner=owner, settings=checked, status=RLModel.Status.IMPORTING
        )
    # Its files are written outside any transaction (the weights may be hundreds of MiB), the
    # model IMPORTING meanwhile; READY once they are all stored, and gone where they cannot be.
    try:
        artifacts.write_model_files(model)
        exact, notes = _exact_history(members)
        best_name, last_name = _checkpoints_save(model, best, last, exact)
        with transaction.atomic():
            job = TrainingJob.objects.create(
                model=model,
                status=TrainingJob.Status.COMPLETED,
                weights_version=1,
                best_checkpoint=best_name,
                last_checkpoint=last_name,
                lease_owner=leases.IMPORTED,
                message="Imported with its weights.",
            )
            history_notes, metrics = _import_history(model, job, members, ours, exact)
            lifecycle.MODEL.move(model, RLModel.Status.READY)
    except BaseException:
        _import_undo(model)
        raise
    # The model is READY before the history's files, up to 1000 traces, are written: a failure
    # there is a note, not a refused import.
    return Imported(
        model,
        notes
        + history_notes
        + _history_files_save(model, metrics, members, iterations=job.iterations),
    )


def _import_undo(model: RLModel) -> None:
    """Take back an import that failed while its files were stored: its files, then its row
    (a failed delete leaves files under the deleted model's prefix, never a row without them)."""
    try:
        artifacts.delete_all(model)
    except Exception:
        logger.exception("Import of model %s failed; its files could not all be deleted", model.pk)
    try:
        model.delete()
    except Exception:  # the database locked, say: the racer reads why the import failed
        logger.exception(
            "Import of model %s failed and its row could not be deleted; the workers' "
            "heartbeat removes it (abandoned_imports_remove)",
            model.pk,
        )


ABANDONED_AFTER = 10 * 60  # [s] an import still IMPORTING this long has died


def abandoned_imports_remove() -> list[str]:
    """Remove each model whose import died while it stored its files (its web process stopped,
    or its undo could not delete the row): IMPORTING for ``ABANDONED_AFTER``. Its files and row
    go, as ``services.model_delete`` takes them, rather than stay as an ERROR model: the racer
    never saw it ready and its files may be partial, so there is nothing in it to keep, and
    they expect its name and their quota free to import it again. What was removed, in words
    for the log; every worker's heartbeat calls it (``console.recovery.resume_lapsed``)."""
    importing = frozenset({RLModel.Status.IMPORTING})
    since = timezone.now() - timedelta(seconds=ABANDONED_AFTER)
    removed = []
    for model in RLModel.objects.filter(status__in=importing, created_at__lt=since):
        if not lifecycle.MODEL.move(model, RLModel.Status.ERROR, only_from=importing):
            continue  # it became READY meanwhile, or another worker took it
        pk = model.pk  # None once deleted
        try:
            services.model_delete(model=model)
        except Exception:  # it stays ERROR, for the racer to delete
            logger.exception("The abandoned import of model %s could not be removed", pk)
            continue
        removed.append(
            f"import of model {pk} stopped as it stored its files; the model was removed"
        )
    return removed


def _exact_history(members: Members) -> tuple[history.Exact | None, list[str]]:
    """Pitlane's exact record of the training (``history.EXACT``), when the archive has one
    that can be read; else None, with a note when it has one that cannot."""
    data = members.get(history.EXACT)
    if data is None and history.EXACT not in members.over:
        return None, []
    try:
        if data is None:
            raise history.Unreadable(f"it is over {size(METRICS_LIMIT)}")
        return history.exact_read(data), []
    except history.Unreadable as unreadable:
        return None, [f"The archive's {history.EXACT} could not be read ({unreadable})."]


def _checkpoints_save(
    model: RLModel, best: bytes, last: bytes, exact: history.Exact | None
) -> tuple[str, str]:
    """The storage names of the best and last weights, saved: where the trainer keeps the
    iteration each holds when the archive says which (so their labels say it), else as an
    import's."""
    names = []
    for which, data in (("best", best), ("last", last)):
        number = exact.checkpoints.get(which) if exact else None
        relative = (
            artifacts.checkpoint(number) if number else f"checkpoints/imported-{which}.safetensors"
        )
        names.append(artifacts.save(model, relative, data))
    return names[0], names[1]


def _import_history(
    model: RLModel, job: TrainingJob, members: Members, ours: dict, exact: history.Exact | None
) -> tuple[list[str], bytes | None]:
    """The job's iterations and totals, exactly as they were from the archive's
    ``history.EXACT``, else rebuilt from its training metrics; notes that say what was rebuilt
    or is missing, and the metrics to keep with the model when they can be read."""
    seconds = ours.get("training_seconds")
    seconds = float(seconds) if isinstance(seconds, int | float) and 0 <= seconds < 10**7 else None
    data = members.get(artifacts.TRAINING_METRICS)
    notes, found = [], None
    try:
        if artifacts.TRAINING_METRICS in members.over:
            raise history.Unreadable(f"it is over {size(METRICS_LIMIT)}")
        if data is None:
            raise history.Unreadable("none")
        found = history.read(
            data, episodes_per_iteration=model.hyperparameters["num_episodes_between_training"]
        )
    except history.Unreadable as unreadable:
        if exact is None:
            missing = data is None and artifacts.TRAINING_METRICS not in members.over
            said = (
                "The archive has no training metrics"
                if missing
                else f"The archive's training metrics could not be read ({unreadable})"
            )
            notes.append(
                f"{said}: the model arrives without its training history (no graph or iterations)."
            )
    if exact is not None:
        history.history_save(job=job, history=exact.history, seconds=seconds)
    elif found is not None:
        history.history_save(job=job, history=found, seconds=seconds)
        notes.append(
            "Training figures rebuilt from DeepRacer's metrics, which round them: the rewards "
            "and completions may differ a little from those the model trained with, and which "
            "iteration the best checkpoint holds is not known (the archive has no "
            f"{history.EXACT})."
        )
    return notes, (data if found is not None else None)


def _history_files_save(
    model: RLModel, metrics: bytes | None, members: Members, *, iterations: int
) -> list[str]:
    """The training metrics (when they could be read) and the archive's training simulation
    traces (those of its iterations, when the history says how many), kept where the Analysis
    tab and the downloads read them; notes for what stays behind, or could not be stored."""
    found = {int(match[1]): path for path in members if (match := TRAINING_TRACE.fullmatch(path))}
    kept = [
        number
        for number, path in sorted(found.items())
        if members[path] is not None and (not iterations or number < iterations)
    ]
    notes, stored = [], 0
    try:
        if metrics is not None:
            artifacts.save(model, artifacts.TRAINING_METRICS, metrics)
        for number in kept:
            artifacts.save(
                model, artifacts.training_trace(number + 1), members[found[number]] or b""
            )
            stored += 1
    except Exception as error:  # storage: the model stands without them
        logger.warning("Model %s imported without all its history files: %s", model.pk, error)
        notes.append(
            f"Storage failed while the archive's training metrics and simulation traces were "
            f"kept: {stored} of its {len(kept)} traces were, which the Analysis tab shows; a "
            "download of this model carries what was kept."
        )
    if not found:
        notes.append(
            "The archive has no simulation traces (training-simtrace): the Analysis tab "
            "has nothing to show."
        )
    elif stored == len(kept) < len(found):
        notes.append(
            f"Simulation traces came for {len(kept)} of the archive's {len(found)} iterations "
            f"(an import keeps up to {size(exports.TRACES_LIMIT)} of them): the Analysis tab "
            "shows those."
        )
    evaluations = sum(1 for path in members if EVALUATION_TRACE.fullmatch(path))
    if evaluations:
        notes.append(
            f"The archive's evaluation traces ({evaluations}) stay in it: evaluations start "
            "afresh here, with their own traces, video and Analysis tab."
        )
    return notes
