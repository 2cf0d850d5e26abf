"""A model's settings, checked as a whole: the create-model page and ``manage.py createmodel``
both come through here, and a model is saved only when everything is valid.

Settings use DeepRacer's vocabulary: sensors and action space as in ``model_metadata.json``,
hyperparameters under the names of ``hyperparameters.json``.

Long because every setting of a model and of an evaluation is checked here, beside the others
it depends on, so that no page or command can save one unchecked.
"""

from __future__ import annotations

import copy
import dataclasses
import re
from collections.abc import Mapping
from typing import Any

from django.db.models import TextChoices

from common.numbers import finite
from common.refusals import Refused
from rl import hyperparameters as hp
from simulator import config as sim
from simulator import tracks as sim_tracks
from training.models import (
    EVALUATION_TRIALS,
    EVALUATION_TRIALS_RANGE,
    SEEDS,
    Algorithm,
    BestCheckpointBy,
    CameraLens,
    Checkpoint,
    Direction,
    Network,
    RLModel,
    ShellColour,
    Track,
    Vehicle,
)
from training.rewards import Validation, reward_validate

NAME = re.compile(r"^[A-Za-z0-9-]{1,64}$")
MINUTES = (10, 1440)
MAX_WORKERS = 4
TRIALS = (3, 5)
SEED_RANGE = f"A seed is a whole number from 0 to {SEEDS - 1}."  # a model's, as an evaluation's
PENALTY_MAX = 10.0  # [s]


class Invalid(Refused):
    """Settings with problems: ``errors`` maps each setting to what is wrong with it."""


Draft = dict[str, Any]
"""A model's settings as a racer gives them, unchecked: from the create-model page
(``ModelCreateForm.settings``), ``manage.py createmodel``'s JSON or an imported archive's files,
under ``ModelSettings``' names (the track by its name; the action space a list, a mapping or
"unreadable": a discrete table that is not JSON). ``check`` makes them ``ModelSettings``; what is
left out takes DeepRacer's default."""


def setting(
    default: Any = dataclasses.MISSING,
    *,
    default_factory: Any = dataclasses.MISSING,
    archived: bool = False,
    drafted: bool = True,
    environment: str = "",
    choices: type[TextChoices] | None = None,
    refusal: str = "",
) -> Any:
    """One of a model's settings, declared once in ``ModelSettings`` with what is derived from it:
    ``archived``, written to an export's pitlane.json and read back by an import (the settings
    DeepRacer's own files do not carry); ``drafted``, given back to ``check`` by ``draft``;
    ``environment``, the simulator's argument it becomes (``environment_of``); ``choices`` and
    ``refusal``, what ``check`` accepts (left out: ``default``) and what it says otherwise."""
    metadata = {
        "archived": archived,
        "drafted": drafted,
        "environment": environment,
        "choices": choices,
        "refusal": refusal,
    }
    return dataclasses.field(default=default, default_factory=default_factory, metadata=metadata)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ModelSettings:
    """A model's settings, checked and complete: the one list of them. ``check`` returns them,
    ``model_create`` saves them (``row``: ``RLModel``'s columns of the same names), the clone page
    shows them again (``of`` a saved model), an export writes and an import reads the
    ``archived`` ones (``archived_of``), and the simulator is made from the ``environment`` ones
    (``environment_of``). Sensors and action space are in the vocabulary of DeepRacer's
    model_metadata.json, hyperparameters under the names of its hyperparameters.json."""

    name: str = setting(archived=True)
    description: str = setting(archived=True)
    track: Track = setting(archived=True, environment="track")
    direction: str = setting(archived=True, environment="direction")
    race_type: str = setting(archived=True, environment="race_type")
    boxes: dict | None = setting(archived=True, environment="objects")
    bots: dict | None = setting(archived=True, environment="bots")
    vehicle: Vehicle | None = setting()
    shell_colour: str = setting(archived=True, environment="car_colour")
    sensors: list[str] = setting(environment="sensors")  # model_metadata.json's
    network: str = setting(
        Network.SHALLOW, choices=Network, refusal="The network is the 3-layer or the 5-layer CNN."
    )
    action_space_type: str = setting(drafted=False)  # the action space's kind
    action_space: list[dict] | dict = setting(environment="action_space")
    algorithm: str = setting()
    hyperparameters: dict = setting()  # hyperparameters.json's
    max_minutes: int = setting(60, archived=True)  # DeepRacer's console's
    workers: int = setting(1, archived=True)
    extra_tracks: list[str] = setting(default_factory=list, archived=True)
    seed: int = setting(0, archived=True)
    reward_function: str = setting()  # reward_function.py
    cloned_from: RLModel | None = setting(None)
    cloned_checkpoint: str = setting("")
    best_checkpoint_by: str = setting(
        BestCheckpointBy.PROGRESS,
        archived=True,
        choices=BestCheckpointBy,
        refusal="Pick the best checkpoint by progress, reward or lap time.",
    )
    evaluation_trials: int = setting(EVALUATION_TRIALS, archived=True)
    camera_lens: str = setting(
        CameraLens.SIMULATOR,
        archived=True,
        environment="camera_lens",
        choices=CameraLens,
        refusal="Choose DeepRacer's simulated camera or the car's wide lens.",
    )
    domain_randomisation: bool = setting(False, archived=True, environment="randomise")
    # blank: the route file the console drives the direction
    world_name: str = setting("", archived=True)
    # a clone's weights are for its source's network, whatever this console's layout now is
    network_layout: int = setting(hp.NETWORK_LAYOUT, archived=True, drafted=False)

    @classmethod
    def of(cls, model: RLModel) -> ModelSettings:
        """A saved model's settings."""
        return cls(**{field.name: getattr(model, field.name) for field in dataclasses.fields(cls)})

    def row(self) -> dict:
        """The settings as ``RLModel`` fields: ``RLModel(owner=..., **settings.row())``."""
        return {field.name: getattr(self, field.name) for field in dataclasses.fields(self)}

    def draft(self) -> Draft:
        """The settings as a racer would give them: ``check`` of these gives them back."""
        return {
            field.name: _given(getattr(self, field.name))
            for field in dataclasses.fields(self)
            if field.metadata["drafted"]
        }

    def replace(self, **changes) -> ModelSettings:
        return dataclasses.replace(self, **changes)


SETTINGS = {field.name: field for field in dataclasses.fields(ModelSettings)}
ARCHIVED = [name for name, field in SETTINGS.items() if field.metadata["archived"]]


def archived_of(model: RLModel) -> dict:
    """The settings an export's pitlane.json holds (``ARCHIVED``), as an import reads them."""
    return {name: _given(getattr(model, name)) for name in ARCHIVED}


def archived_draft(ours: dict) -> Draft:
    """The settings an export's pitlane.json (``ours``) gives, for ``check``; one it leaves out (an
    older export's, written before the setting existed, or another console's) is the setting's
    default where it has one."""
    draft = {}
    for name in ARCHIVED:
        declared = SETTINGS[name]
        if not declared.metadata["drafted"]:
            continue
        if name in ours:
            draft[name] = ours[name]
        elif (default := default_of(name)) is not dataclasses.MISSING:
            draft[name] = default
    return draft


def default_of(name: str) -> Any:
    """A setting's default (``dataclasses.MISSING`` for one a racer must give)."""
    declared = SETTINGS[name]
    if declared.default_factory is not dataclasses.MISSING:
        return declared.default_factory()
    return declared.default


def environment_of(model: RLModel) -> dict:
    """The simulator's arguments from a model's settings (``RLModel.environment_settings``)."""
    made = {
        field.metadata["environment"]: _given(getattr(model, name))
        for name, field in SETTINGS.items()
        if field.metadata["environment"]
    }
    made["car_colour"] = ShellColour.bgr(made["car_colour"])
    return made


def _given(value):
    """A setting's value as a racer gives it: a track by its name, lists copied."""
    if isinstance(value, Track):
        return value.name
    if isinstance(value, list | dict):
        return copy.deepcopy(value)
    return value


def name_problem(name: str, *, owner) -> str | None:
    """What is wrong with ``name`` for a new model of ``owner``'s, or None."""
    if not NAME.match(name):
        return "A model's name is 1-64 letters, digits and hyphens."
    if RLModel.objects.filter(owner=owner, name__iexact=name).exists():
        return f"You already have a model named “{name}”; choose another name."
    return None


def check(
    settings: Draft,
    *,
    owner,
    validate_reward: bool = True,
    reward_required: bool = True,
    validation: Validation | None = None,
) -> ModelSettings:
    """The settings, complete and typed; ``Invalid`` otherwise, with every problem found.
    Only a model imported without a reward function (to evaluate and race, not to train) is
    checked without ``reward_required``. The reward function is validated here unless
    ``validation`` is given: its result, found by a checker (``training.checkers``) on
    ``reward_sample_track(settings)``, for the same code."""
    errors: dict[str, str] = {}
    clean: dict = {}
    _check_identity(settings, clean, errors, owner)
    track = _check_track(settings, clean, errors)
    clean["world_name"] = _world_name(settings, track)
    _check_race(settings, clean, errors)
    _check_car(settings, clean, errors, owner)
    _check_algorithm(settings, clean, errors)
    _check_schedule(settings, clean, errors)
    for name, declared in SETTINGS.items():
        if declared.metadata["choices"]:
            _check_choice(settings, clean, errors, name)
    source = settings.get("reward_function") or ""
    if not source.strip():
        if reward_required:
            errors["reward_function"] = "Write a reward function (or start from an example)."
    elif validate_reward and track is not None and "direction" not in errors:
        problem = _reward_problem(source, track, clean["direction"], validation)
        if problem is not None:
            errors["reward_function"] = problem
    clean["reward_function"] = source
    source_model = settings.get("cloned_from")
    if isinstance(source_model, RLModel):
        errors.update(_clone_errors(source_model, clean))
        clean["cloned_from"] = source_model
        which = str(settings.get("cloned_checkpoint") or Checkpoint.BEST)
        clean["cloned_checkpoint"] = which
        if which not in Checkpoint.values and not (which.isdigit() and 0 < int(which) < 10**7):
            errors["cloned_checkpoint"] = (
                "Start the clone from the best or the last checkpoint, or an iteration's number."
            )
    if errors:
        raise Invalid(errors)
    return ModelSettings(**clean)


def _check_identity(settings: dict, clean: dict, errors: dict, owner) -> None:
    name = str(settings.get("name", "")).strip()
    if problem := name_problem(name, owner=owner):
        errors["name"] = problem
    clean["name"] = name
    description = str(settings.get("description") or "")
    if len(description) > 255:
        errors["description"] = "The description is at most 255 characters."
    clean["description"] = description


def _check_algorithm(settings: dict, clean: dict, errors: dict) -> None:
    algorithm = settings.get("algorithm") or Algorithm.PPO
    if algorithm not in Algorithm.values:
        errors["algorithm"] = "The algorithm is PPO or SAC."
    elif algorithm == Algorithm.SAC and clean.get("action_space_type") == "discrete":
        errors["algorithm"] = "SAC needs a continuous action space; choose PPO for a discrete one."
    else:
        values, problems = hp.check(algorithm, settings.get("hyperparameters") or {})
        errors.update({f"hyperparameters.{key}": message for key, message in problems.items()})
        clean["hyperparameters"] = values
    clean["algorithm"] = algorithm


def _check_schedule(settings: dict, clean: dict, errors: dict) -> None:
    """How long and on how many simulations (and extra tracks) the model trains, its seed, and
    how many evaluation episodes each checkpoint drives."""
    minutes = _integer(settings.get("max_minutes", default_of("max_minutes")))
    if minutes is None or not MINUTES[0] <= minutes <= MINUTES[1]:
        errors["max_minutes"] = (
            f"The maximum training time is {MINUTES[0]} to {MINUTES[1]} minutes."
        )
    clean["max_minutes"] = minutes
    workers = _integer(settings.get("workers", default_of("workers")))
    if workers is None or not 1 <= workers <= MAX_WORKERS:
        errors["workers"] = f"A model trains in 1 to {MAX_WORKERS} simulations at once."
    clean["workers"] = workers
    extra = [str(name) for name in settings.get("extra_tracks") or []]
    if workers and len(extra) > workers - 1:
        errors["extra_tracks"] = "Each extra track needs a simulation of its own."
    known = set(Track.objects.filter(name__in=extra).values_list("name", flat=True))
    if set(extra) - known:
        errors["extra_tracks"] = "Choose extra tracks from the listed ones."
    clean["extra_tracks"] = extra
    # An imported model's seed (its pitlane.json): one the trainer cannot take fails its training
    # at once, and one the database cannot hold failed the import with a 500.
    given = settings.get("seed")
    clean["seed"] = default_of("seed") if given is None else _integer(given)
    if clean["seed"] is None or not 0 <= clean["seed"] < SEEDS:
        errors["seed"] = SEED_RANGE
    given = settings.get("evaluation_trials")
    trials = default_of("evaluation_trials") if given in (None, "") else _integer(given)
    low, high = EVALUATION_TRIALS_RANGE
    if trials is None or not low <= trials <= high:
        errors["evaluation_trials"] = (
            f"Each checkpoint drives {low} to {high} evaluation episodes (DeepRacer's "
            f"{EVALUATION_TRIALS})."
        )
    clean["evaluation_trials"] = trials
    clean["domain_randomisation"] = _switch(settings, "domain_randomisation", errors)


def _reward_problem(
    source: str, track: Track, direction: str, validation: Validation | None
) -> str | None:
    """What is wrong with the reward function ``source`` (its first error), or None: validated
    here on ``track`` unless ``validation`` (of the same code) is given."""
    if validation is None:
        result = reward_validate(source=source, track=track.name, direction=direction)
    elif validation.source != source:
        raise ValueError("The validation given is of other code than the settings'.")
    else:
        result = validation
    if result.valid:
        return None
    first = result.errors[0]
    line = f" (line {first.line})" if first.line else ""
    return f"{first.type}{line}: {first.message}"


def _clone_errors(source: RLModel, clean: dict) -> dict[str, str]:
    """What a clone may not change: its weights must fit the network it starts from."""
    if source.status != RLModel.Status.READY:
        return {"cloned_from": "Only a ready model can be cloned."}
    errors = {}
    if sorted(source.sensors) != sorted(clean.get("sensors") or []):
        errors["sensors"] = (
            f"A clone keeps its source's sensors ({', '.join(source.sensors)}); it learns from "
            "the same inputs."
        )
    if "network" in clean and clean["network"] != source.network:
        errors["network"] = "A clone keeps its source's network: its weights are for that one."
    if "algorithm" in clean and clean["algorithm"] != source.algorithm:
        errors["algorithm"] = (
            f"A clone keeps its source's training algorithm ({source.get_algorithm_display()})."
        )
    space = clean.get("action_space")
    if "action_space" in clean and clean.get("action_space_type") != source.action_space_type:
        errors["action_space"] = (
            f"A clone keeps its source's {source.action_space_type} action space; you may "
            "change the actions' angles and speeds, not their kind."
        )
    elif isinstance(space, list) and len(space) != len(source.action_space):
        errors["action_space"] = (
            f"A clone keeps its source's number of actions ({len(source.action_space)}); you "
            "may change their angles and speeds."
        )
    return errors


def check_evaluation(settings: dict, *, model: RLModel) -> dict:
    """An evaluation's settings, complete and typed, ready for ``EvaluationJob(**...)``;
    ``Invalid`` otherwise. Unset settings take DeepRacer's defaults and the model's track."""
    errors: dict[str, str] = {}
    clean: dict = {}
    settings = {"track": model.track.name, "direction": model.direction, **settings}
    _check_track(settings, clean, errors)
    _check_race(settings, clean, errors)
    trials = _integer(settings.get("trials", 3))
    if trials is None or not TRIALS[0] <= trials <= TRIALS[1]:
        errors["trials"] = f"An evaluation has {TRIALS[0]} to {TRIALS[1]} trials."
    clean["trials"] = trials
    clean["continuous_laps"] = bool(settings.get("continuous_laps", False))
    for name, default in (("off_track_penalty", 2.0), ("crash_penalty", 5.0)):
        value = finite(settings.get(name, default))
        if value is None or not 0 <= value <= PENALTY_MAX:
            what = name.replace("_", " ").capitalize()
            errors[name] = f"{what} is 0 to {PENALTY_MAX:g} seconds."
        clean[name] = value
    resets = settings.get("max_resets", sim.DEFAULT_MAX_RESETS)
    if resets is not None:  # None: the car is put back for as long as the trial lasts
        resets = _integer(resets)
        if resets is None or not 0 <= resets <= sim.MAX_RESETS:
            errors["max_resets"] = f"Resets allowed is a whole number from 0 to {sim.MAX_RESETS:,}."
    clean["max_resets"] = resets
    checkpoint = settings.get("checkpoint") or "best"
    if checkpoint not in ("best", "last"):
        errors["checkpoint"] = "Evaluate the best or the last checkpoint."
    clean["checkpoint"] = checkpoint
    clean["domain_randomisation"] = _switch(settings, "domain_randomisation", errors)
    if errors:
        raise Invalid(errors)
    return clean


def check_race(settings: dict) -> dict:
    """A race type with its boxes or bots (``race_type``, ``boxes``, ``bots``), complete and
    typed; ``Invalid`` otherwise."""
    clean: dict = {}
    errors: dict[str, str] = {}
    _check_race(settings, clean, errors)
    if errors:
        raise Invalid(errors)
    return clean


def reward_sample_track(settings: Draft) -> tuple[str, str] | None:
    """(track, direction): where ``check`` validates the reward function of ``settings``; None
    when it will not, for the settings name no track (or a direction it is not driven in)."""
    clean: dict = {}
    errors: dict = {}
    track = _check_track(settings, clean, errors)
    if track is None or errors:
        return None
    return track.name, clean["direction"]


def direction_words(direction: str) -> str:
    """A direction as every page writes it ("counter-clockwise"), not as it is stored."""
    return str(dict(Direction.choices).get(direction, direction)).lower()


def _check_track(settings: dict, clean: dict, errors: dict) -> Track | None:
    track = Track.objects.filter(name=settings.get("track")).first()
    if track is None:
        errors["track"] = "Choose one of the listed tracks."
    clean["track"] = track
    direction = settings.get("direction") or "counterclockwise"
    if track is not None and direction not in _directions(track):
        errors["direction"] = f"{track} cannot be driven {direction_words(direction)}."
    clean["direction"] = direction
    return track


def _world_name(settings: dict, track: Track | None) -> str:
    """The route file the model drives (``RLModel.world_name``): an import's, or a clone's
    source's where the clone keeps its track; none where it is not one of ``track``'s files (a
    racer who chose another track chose that track's route)."""
    world_name = str(settings.get("world_name") or "")
    source = settings.get("cloned_from")
    if not world_name and isinstance(source, RLModel) and track is not None:
        world_name = source.world_name if source.track_id == track.pk else ""
    found = sim_tracks.world(world_name) if world_name and track is not None else None
    return world_name if found and found[0] == track.name else ""


def _check_race(settings: dict, clean: dict, errors: dict) -> None:
    race_type = settings.get("race_type") or "TIME_TRIAL"
    try:
        sim.choice("The race type", race_type, sim.RACE_TYPES)
        boxes = sim.objects(
            settings.get("boxes") if race_type == "OBJECT_AVOIDANCE" else None, race_type
        )
        bots = sim.bots(settings.get("bots") if race_type == "HEAD_TO_BOT" else None, race_type)
    except sim.ConfigError as error:
        errors["race_type"] = str(error)
        boxes = bots = None
    clean["race_type"] = race_type
    clean["boxes"] = vars(boxes) if boxes else None
    clean["bots"] = vars(bots) if bots else None


def _check_car(settings: dict, clean: dict, errors: dict, owner) -> None:
    vehicle = settings.get("vehicle")
    if vehicle is not None and (not isinstance(vehicle, Vehicle) or vehicle.owner_id != owner.pk):
        errors["vehicle"] = "Choose one of the vehicles in your garage."
        vehicle = None
    clean["vehicle"] = vehicle
    clean["shell_colour"] = (
        vehicle.shell_colour if vehicle else settings.get("shell_colour") or ShellColour.BLACK
    )
    if clean["shell_colour"] not in ShellColour.values:
        errors["shell_colour"] = "Choose one of the garage's colours."
    sensors = settings.get("sensors") or ["FRONT_FACING_CAMERA"]
    try:
        camera, lidar = sim.sensors(sensors)
        clean["sensors"] = [camera, lidar] if lidar else [camera]
    except sim.ConfigError as error:
        errors["sensors"] = str(error)
        clean["sensors"] = []
    space = settings.get("action_space")
    try:
        actions = sim.action_space(space)
    except sim.ActionSpaceError as error:
        for place, message in error.problems.items():
            errors["action_space" + (f".{place}" if place else "")] = message
        # the kind the racer chose, so that no other check blames the kind for a bad value
        kind = "continuous" if isinstance(space, Mapping) else "discrete"
        clean["action_space_type"], clean["action_space"] = kind, None
        return
    if isinstance(actions, sim.ContinuousActions):
        clean["action_space_type"], clean["action_space"] = "continuous", actions.metadata()
    else:
        clean["action_space_type"], clean["action_space"] = "discrete", actions.metadata()


def _directions(track: Track) -> list[str]:
    return [name for name in ("counterclockwise", "clockwise") if getattr(track, name)]


def _check_choice(settings: dict, clean: dict, errors: dict, name: str) -> None:
    """A setting with ``choices`` (``ModelSettings``): its default when left out."""
    declared = SETTINGS[name]
    clean[name] = settings.get(name) or declared.default
    if clean[name] not in declared.metadata["choices"].values:
        errors[name] = declared.metadata["refusal"]


def _switch(settings: dict, name: str, errors: dict) -> bool:
    """An on-off setting (false when left out); anything but true or false is refused."""
    value = settings.get(name, False)
    if not isinstance(value, bool):
        errors[name] = f"{name.replace('_', ' ').capitalize()} is on or off: true or false."
    return value is True


def _integer(value) -> int | None:
    number = finite(value)
    return int(number) if number is not None and number == int(number) else None
