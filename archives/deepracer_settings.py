"""DeepRacer's files mapped to a model's settings, field by field (``archives.imports``):
model_metadata.json, hyperparameters.json and training_params.yaml as the DeepRacer console and
DeepRacer for Cloud write them, with a note for each setting this console reads differently or
leaves out.

Long because each of DeepRacer's settings is mapped here, with its note, beside the others.
"""

from __future__ import annotations

import json
import re

import numpy as np

from archives.members import ImportRefused, Members, member_json, member_place, member_yaml
from rl import hyperparameters
from simulator import config as sim
from simulator import tracks as sim_tracks
from training import configuration
from training.models import (
    EVALUATION_TRIALS,
    EVALUATION_TRIALS_RANGE,
    Algorithm,
    BestCheckpointBy,
    Network,
    ShellColour,
    Track,
)

DEFAULT_TRACK = "rookie-loop"


SENSOR_ALIASES = {sim.LEGACY_CAMERA: "FRONT_FACING_CAMERA"}


DEEPRACER_ALGORITHMS = {
    hyperparameters.PPO: Algorithm.PPO,
    "ppo": Algorithm.PPO,
    hyperparameters.SAC: Algorithm.SAC,
}


def archive_settings(
    metadata: dict,
    ours: dict,
    members: Members,
    reward: str,
    name: str,
    notes: list[str],
    track_notes: list[str] | None = None,
) -> configuration.Draft:
    """The create-model settings the archive describes, unchecked; what it leaves out takes the
    defaults, and ``notes`` lists every setting it has that could not be carried over (those on
    its track in ``track_notes`` too)."""
    params = member_yaml(members, member_place(members, "training_params.yaml"))
    algorithm = DEEPRACER_ALGORITHMS.get(
        str(metadata.get("training_algorithm", Algorithm.PPO)).lower(), "unknown"
    )
    if algorithm == "unknown":
        raise ImportRefused(
            f"model_metadata.json names the algorithm {metadata.get('training_algorithm')!r}; "
            "this console trains PPO (clipped_ppo) and SAC."
        )
    given = member_json(members, member_place(members, "hyperparameters.json")) or {}
    settings: configuration.Draft = {
        **configuration.archived_draft(ours),  # a Pitlane export's; what it left out: defaults
        "name": name or ours.get("name") or _model_name(params),
        "description": str(ours.get("description") or "Imported."),
        "sensors": _sensors(metadata, notes),
        "network": _network(metadata, notes),
        "action_space": metadata.get("action_space"),
        "algorithm": algorithm,
        "hyperparameters": _hyperparameters(algorithm, given, notes),
        "reward_function": reward,
    }
    _metadata_left_out(metadata, notes)
    if ours.get("track"):  # a Pitlane export: its settings; training_params.yaml repeats them
        return settings
    on_track: list[str] = []
    settings["track"], settings["direction"], settings["world_name"] = deepracer_track(
        params, on_track
    )
    notes += on_track
    if track_notes is not None:
        track_notes += on_track
    settings.update(_deepracer_race(params, notes))
    settings["workers"] = _deepracer_workers(params, notes)
    settings["shell_colour"] = _deepracer_colour(params, notes)
    settings["domain_randomisation"] = _deepracer_randomisation(params, notes)
    settings["best_checkpoint_by"] = _deepracer_best_metric(params, notes)
    settings["evaluation_trials"] = _deepracer_evaluation_trials(params, notes)
    _params_left_out(params, notes)
    return settings


def _model_name(params: dict) -> str:
    """DeepRacer's model name as one of ours (letters, digits and hyphens), or a stand-in."""
    raw = str(params.get("CAR_NAME") or "")
    cleaned = "-".join(re.findall(r"[A-Za-z0-9]+", raw))[:64].strip("-")
    return cleaned or "imported-model"


def shown(value) -> str:
    return value if isinstance(value, str) else json.dumps(value, default=str)


def _hyperparameters(algorithm: str, given: dict, notes: list[str]) -> dict:
    """The archive's hyperparameters this console can take, checked one at a time: each one out
    of range, or not DeepRacer's, is left at its default and noted."""
    values, unknown = {}, []
    for key, value in given.items():
        setting = hyperparameters.setting(algorithm, key)
        if setting is None:
            unknown.append(f"{key} {shown(value)}")
            continue
        try:
            values[key] = setting.check(value)
        except ValueError as error:
            default = hyperparameters.spelled(algorithm, key, setting.default)
            notes.append(
                f"Not carried over from hyperparameters.json: {key} {shown(value)}. {error} "
                f"The model uses {shown(default)}."
            )
    if unknown:
        notes.append(
            f"Not carried over from hyperparameters.json: {', '.join(unknown)}: not "
            "one of DeepRacer's hyperparameters."
        )
    return values


def _sensors(metadata: dict, notes: list[str]) -> list[str]:
    """The archive's sensors this console has; the others are noted. A car without a camera
    gets the front-facing one, as DeepRacer's older models had (model_metadata.py:230-242)."""
    given = metadata.get("sensor") or ["FRONT_FACING_CAMERA"]
    if isinstance(given, str) or not isinstance(given, list):
        raise ImportRefused('model_metadata.json\'s "sensor" must be a list of sensors.')
    given = [SENSOR_ALIASES.get(str(sensor), str(sensor)) for sensor in given]
    camera = next((s for s in given if s in sim.CAMERAS), None)
    lidar = next((s for s in given if s in sim.LIDARS), None)
    kept = [camera or "FRONT_FACING_CAMERA"] + ([lidar] if lidar else [])
    dropped = [s for s in given if s not in kept]
    if dropped:
        notes.append(
            f"Not carried over from model_metadata.json: the sensor{'s' * (len(dropped) > 1)} "
            f"{', '.join(dropped)}. This console's cars have {' or '.join(sim.CAMERAS)} and at "
            f"most one of {', '.join(sim.LIDARS)}; the model has {', '.join(kept)}."
        )
    elif camera is None:
        notes.append("model_metadata.json names no camera: the model has FRONT_FACING_CAMERA.")
    return kept


def _network(metadata: dict, notes: list[str]) -> str:
    """The archive's network (DeepRacer's default is the shallow one: model_metadata.py:290-293)."""
    network = metadata.get("neural_network") or Network.SHALLOW
    if network in Network.values:
        return network
    notes.append(
        f"Not carried over from model_metadata.json: the network {shown(network)}. This "
        f"console trains {' and '.join(Network.values)}; the model has {Network.SHALLOW}."
    )
    return Network.SHALLOW


# model_metadata.json's keys (simapp bundle/markov/boto/s3/constants.py:90-106, 01f5f01) that the
# settings above take, or that describe the file rather than the model.
METADATA_TAKEN = {
    "sensor",
    "neural_network",
    "action_space",
    "action_space_type",
    "training_algorithm",
    "version",
}


def _metadata_left_out(metadata: dict, notes: list[str]) -> None:
    left = [f"{key} {shown(value)}" for key, value in metadata.items() if key not in METADATA_TAKEN]
    if left:
        notes.append(f"Not carried over from model_metadata.json: {'; '.join(left)}.")


def _truthy(value) -> bool:
    """A YAML flag as simapp reads it (bundle/markov/utils.py:129-136, 01f5f01): "true" or a
    true boolean."""
    return value is True or str(value).strip().lower() == "true"


ROUTE_NOTE = "Trains on "  # how the note begins that says which route file the model drives


def is_route_note(note: str) -> bool:
    """Whether ``note`` says which route file the model drives (``deepracer_track``): what is
    carried over and used, not what was left out."""
    return note.startswith(ROUTE_NOTE)


def deepracer_track(params: dict, notes: list[str]) -> tuple[str, str, str]:
    """``WORLD_NAME`` as one of our tracks, the direction to drive it, and the route file to
    drive where DeepRacer drove one the console does not (``RLModel.world_name``, else ""). The
    name as it is first; then without DeepRacer's ``_cw``/``_ccw`` suffix, which also gives the
    direction (simapp bundle/markov/boto/s3/files/yaml_file.py:228-244, 01f5f01; constants.py
    WorldNameSuffix); then lower-cased with hyphens for underscores. Without a suffix,
    ``TRACK_DIRECTION_CLOCKWISE`` gives the direction, else the route's own; ``REVERSE_DIR``
    turns it round. A track not loaded here is noted, and the model gets ``DEFAULT_TRACK``."""
    world = str(params.get("WORLD_NAME") or "").strip()
    suffixed = {"_cw": "clockwise", "_ccw": "counterclockwise"}
    stem, suffix_direction = world, None
    for suffix, direction in suffixed.items():
        if world.lower().endswith(suffix) and len(world) > len(suffix):
            stem, suffix_direction = world[: -len(suffix)], direction
    candidates = [(world, None), (stem, suffix_direction),
                  (_variant(world), None), (_variant(stem), suffix_direction)]  # fmt: skip
    found = {t.name: t for t in Track.objects.filter(name__in=[c for c, _ in candidates if c])}
    track, direction = next(
        ((found[c], d) for c, d in candidates if c in found), (None, suffix_direction)
    )
    if track is None:
        track = Track.objects.filter(name=DEFAULT_TRACK).first()
        if world:
            shown = track.display_name if track else DEFAULT_TRACK
            notes.append(
                f"Not carried over from training_params.yaml: the track {world}, which "
                f"is not loaded here. The model trains on {shown}; choose "
                "another by cloning it."
            )
    if direction is None and "TRACK_DIRECTION_CLOCKWISE" in params:
        clockwise = _truthy(params["TRACK_DIRECTION_CLOCKWISE"])
        direction = "clockwise" if clockwise else "counterclockwise"
    if direction is None:
        direction = _route_direction(track.name if track else DEFAULT_TRACK)
    if _truthy(params.get("REVERSE_DIR")):
        direction = "clockwise" if direction == "counterclockwise" else "counterclockwise"
    if track is not None and not getattr(track, direction):
        other = "clockwise" if direction == "counterclockwise" else "counterclockwise"
        said, instead = map(configuration.direction_words, (direction, other))
        notes.append(
            f"{track.display_name} is not driven {said} here: the model drives it {instead}."
        )
        direction = other
    if track is None:
        return DEFAULT_TRACK, direction, ""
    driven = world  # the file simapp drove: suffixed by TRACK_DIRECTION_CLOCKWISE where given
    if "TRACK_DIRECTION_CLOCKWISE" in params and suffix_direction is None:
        driven += "_cw" if _truthy(params["TRACK_DIRECTION_CLOCKWISE"]) else "_ccw"
    route = _own_route(driven, track.name, direction)
    if route:
        drove = sim_tracks.load(track.name).on_route(route).with_direction(direction)
        notes.append(
            f"{ROUTE_NOTE}{route}.npy ({len(drove.waypoints)} waypoints), the route file "
            f"DeepRacer drove for WORLD_NAME {world}, not the one DeepRacer's console "
            f"drives {track.display_name} {configuration.direction_words(direction)}: "
            "a reward function that reads waypoints by index sees the route it was "
            "written for."
        )
    return track.name, direction, route


def _own_route(driven: str, name: str, direction: str) -> str:
    """``driven`` (the route file simapp drove: WORLD_NAME, suffixed where
    TRACK_DIRECTION_CLOCKWISE was given) where it is one of track ``name``'s files and its
    waypoints, driven ``direction``, are not those of the file the console drives that way (by
    DeepRacer for Cloud's bare WORLD_NAME: defaults/template-worker.env:1,
    DR_WORLD_NAME=reInvent2019_track; scripts/droa/import_model.py:371); else ""."""
    found = sim_tracks.world(driven)
    if found is None or found[0] != name:
        return ""
    ours = sim_tracks.load(name).with_direction(direction)
    theirs = sim_tracks.load(name).on_route(driven).with_direction(direction)
    mine, drove = np.asarray(ours.waypoints), np.asarray(theirs.waypoints)
    return "" if mine.shape == drove.shape and np.allclose(mine, drove) else driven


def _variant(name: str) -> str:
    return name.lower().replace("_", "-")


def _route_direction(name: str) -> str:
    """The way a track's route runs: what DeepRacer drives on a world without a suffix (a
    built-in DeepRacer track's own file, which may run against the console's default way:
    reInvent2019_wide.npy runs counter-clockwise, the console offered it clockwise first)."""
    found = sim_tracks.world(name)
    if found is not None:
        return found[1]
    try:
        return sim_tracks.load(name).direction
    except (ValueError, OSError, EOFError):  # a route that cannot be read: the default way
        return "counterclockwise"


# training_params.yaml's race settings (simapp YamlKey, boto/s3/constants.py:144-170, and
# D's prepare-config), as our race types take them.
RACE_KEYS = {
    "OBJECT_AVOIDANCE": {
        "NUMBER_OF_OBSTACLES": "count",
        "RANDOMIZE_OBSTACLE_LOCATIONS": "randomize",
    },
    "HEAD_TO_BOT": {
        "NUMBER_OF_BOT_CARS": "count",
        "BOT_CAR_SPEED": "speed",
        "IS_LANE_CHANGE": "lane_changes",
    },
}


def _deepracer_race(params: dict, notes: list[str]) -> dict:
    """The race type and its boxes or bot cars; what does not fit is noted and defaulted."""
    race_type = str(params.get("RACE_TYPE") or "TIME_TRIAL").strip().upper()
    if race_type not in sim.RACE_TYPES:
        notes.append(
            f"Not carried over from training_params.yaml: the race type {race_type}. "
            "The model trains for a TIME_TRIAL."
        )
        return {"race_type": "TIME_TRIAL", "boxes": None, "bots": None}
    race = {"race_type": race_type, "boxes": None, "bots": None}
    if race_type == "TIME_TRIAL":
        return race
    given = {}
    for key, field_name in RACE_KEYS[race_type].items():
        if key in params:
            value = params[key]
            given[field_name] = (
                _truthy(value) if field_name in ("randomize", "lane_changes") else value
            )
    which, check = ("boxes", sim.objects) if race_type == "OBJECT_AVOIDANCE" else ("bots", sim.bots)
    try:
        race[which] = vars(check(given, race_type))
    except (sim.ConfigError, TypeError, ValueError) as error:
        race[which] = vars(check({}, race_type))
        notes.append(
            f"Not carried over from training_params.yaml: {_race_given(params, race_type)}"
            f" ({error}). The model has {_race_shown(race[which])}."
        )
    return race


def _race_given(params: dict, race_type: str) -> str:
    return ", ".join(f"{key} {shown(params[key])}" for key in RACE_KEYS[race_type] if key in params)


def _race_shown(values: dict) -> str:
    return ", ".join(f"{key.replace('_', ' ')} {shown(value)}" for key, value in values.items())


def _deepracer_workers(params: dict, notes: list[str]) -> int:
    """DeepRacer's rollout workers (``NUM_WORKERS``) as our simulations at once."""
    if "NUM_WORKERS" not in params:
        return 1
    try:
        workers = int(params["NUM_WORKERS"])
    except (TypeError, ValueError):
        workers = 0
    if 1 <= workers <= configuration.MAX_WORKERS:
        return workers
    chosen = min(max(workers, 1), configuration.MAX_WORKERS)
    notes.append(
        f"Not carried over from training_params.yaml: NUM_WORKERS {shown(params['NUM_WORKERS'])}."
        f" A model trains in 1 to {configuration.MAX_WORKERS} simulations at once here; it has "
        f"{chosen}."
    )
    return chosen


def _deepracer_colour(params: dict, notes: list[str]) -> str:
    """``CAR_COLOR`` (a colour's name in DeepRacer) as one of the garage's shells."""
    given = params.get("CAR_COLOR")
    if given in (None, ""):
        return ShellColour.BLACK
    by_name = {label.lower(): value for value, label in ShellColour.choices}
    found = by_name.get(str(given).strip().lower())
    if found is None:
        notes.append(
            f"Not carried over from training_params.yaml: CAR_COLOR {shown(given)}, "
            "not one of the garage's colours. The car is black."
        )
        return ShellColour.BLACK
    return found


def _deepracer_randomisation(params: dict, notes: list[str]) -> bool:
    """``ENABLE_DOMAIN_RANDOMIZATION`` (DeepRacer for Cloud writes DR_ENABLE_DOMAIN_RANDOMIZATION
    there, scripts/training/prepare-config.py:54). simapp reads it with str2bool
    (bundle/markov/utils.py:129-136, rollout_worker.py:774, 01f5f01), which makes booleans of
    true and false alone and passes any other text on, where deepracer_racetrack_env.py:222's
    ``if`` takes it as on ('yes', '1', even 'no'). We take true or false, and leave anything
    else off with a note rather than guess."""
    given = params.get("ENABLE_DOMAIN_RANDOMIZATION")
    if given is None or given is False or str(given).strip().lower() in ("", "false"):
        return False
    if _truthy(given):
        return True
    notes.append(
        f"Not carried over from training_params.yaml: ENABLE_DOMAIN_RANDOMIZATION "
        f"{shown(given)}, neither true nor false. Domain randomisation is off."
    )
    return False


def _deepracer_best_metric(params: dict, notes: list[str]) -> str:
    """``BEST_MODEL_METRIC`` (DR_TRAIN_BEST_MODEL_METRIC, prepare-config.py:58): progress,
    reward or laptime in any case, as simapp reads it (s3_metrics.py:267-268,
    metrics/constants.py:163-167, 01f5f01); else progress, DeepRacer's default, with a note."""
    given = params.get("BEST_MODEL_METRIC")
    if given is None or str(given).strip() == "":
        return BestCheckpointBy.PROGRESS
    metric = str(given).strip().lower()
    if metric in BestCheckpointBy.values:
        return metric
    notes.append(
        f"Not carried over from training_params.yaml: BEST_MODEL_METRIC {shown(given)}, "
        "neither progress, reward nor laptime. Training picks the best checkpoint by progress."
    )
    return BestCheckpointBy.PROGRESS


def _deepracer_evaluation_trials(params: dict, notes: list[str]) -> int:
    """``MIN_EVAL_TRIALS`` (DR_TRAIN_MIN_EVAL_TRIALS, which DeepRacer for Cloud writes as text,
    prepare-config.py:55, 2eb1a1f; simapp reads it with int(), rollout_worker.py:501-504,
    01f5f01): the evaluation episodes a checkpoint drives. One this console cannot take is
    brought within its range, with a note."""
    given = params.get("MIN_EVAL_TRIALS")
    if given is None or str(given).strip() == "":
        return EVALUATION_TRIALS
    low, high = EVALUATION_TRIALS_RANGE
    try:
        trials = int(str(given).strip())
    except ValueError:
        trials = None
    if trials is not None and low <= trials <= high:
        return trials
    chosen = EVALUATION_TRIALS if trials is None else min(max(trials, low), high)
    notes.append(
        f"Not carried over from training_params.yaml: MIN_EVAL_TRIALS {shown(given)}. Each "
        f"checkpoint drives {low} to {high} evaluation episodes here; this one drives {chosen}."
    )
    return chosen


# training_params.yaml's keys the settings above take.
PARAMS_TAKEN = {
    "WORLD_NAME",
    "TRACK_DIRECTION_CLOCKWISE",
    "REVERSE_DIR",
    "RACE_TYPE",
    "CAR_NAME",
    "NUM_WORKERS",
    "CAR_COLOR",
    "ENABLE_DOMAIN_RANDOMIZATION",
    "BEST_MODEL_METRIC",
    "MIN_EVAL_TRIALS",
    *RACE_KEYS["OBJECT_AVOIDANCE"],
    *RACE_KEYS["HEAD_TO_BOT"],
}


# Where DeepRacer kept its files and streams, and who ran it: nothing a model here could use.
PARAMS_PLACES = re.compile(
    r"(S3|BUCKET|PREFIX|REGION|ENDPOINT|ARN|KINESIS|SQS|_KEY$|JOB_TYPE|ROBOMAKER|SAGEMAKER)"
)


def _params_left_out(params: dict, notes: list[str]) -> None:
    """Notes for the rest of training_params.yaml: the settings this console cannot honour
    each with its value, and (in one line) where DeepRacer stored its files."""
    left, places = [], []
    for key, value in params.items():
        key = str(key)
        if key in PARAMS_TAKEN:
            continue
        if PARAMS_PLACES.search(key):
            places.append(key)
        else:
            left.append(f"{key} {shown(value)}")
    if left:
        notes.append(f"Not carried over from training_params.yaml: {', '.join(left)}.")
    if places:
        notes.append(
            f"Not carried over from training_params.yaml: where DeepRacer kept the model's files "
            f"and streams ({', '.join(places)}); this console keeps its own."
        )
