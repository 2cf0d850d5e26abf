"""The training app's forms: the create-model page, the evaluation, the garage and the reward
function library.

Long because the create-model form alone carries every setting DeepRacer's console has (sensors,
the action space's table or ranges, each algorithm's hyperparameters, the race type and its
obstacles), each with its own words for what is wrong.
"""

import json
import re
from dataclasses import dataclass

from django import forms

from common.forms import RacerWords
from rl import hyperparameters
from simulator import config as sim
from simulator import randomisation_ranges
from training import configuration, selectors
from training.models import (
    EVALUATION_TRIALS,
    EVALUATION_TRIALS_RANGE,
    Algorithm,
    BestCheckpointBy,
    CameraLens,
    EvaluationJob,
    Network,
    RaceType,
    Track,
    TrackLine,
    Vehicle,
)
from training.rewards import MAX_SOURCE_SIZE


class VehicleForm(RacerWords, forms.ModelForm):
    """Build a vehicle; the owner comes from the request, never from the form."""

    class Meta:
        model = Vehicle
        fields = ["name", "shell_colour", "camera", "lidar"]
        widgets = {"shell_colour": forms.RadioSelect, "camera": forms.RadioSelect}
        help_texts = {
            "camera": "Stereo cameras judge distance: useful when racing around objects.",
            "lidar": "Lidar sees behind and beside the car: useful against bot cars.",
        }

    def __init__(self, *args, owner, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.owner = owner
        self.fields["name"].error_messages["required"] = "Give your vehicle a name."
        self.fields["shell_colour"].error_messages.update(
            required="Choose a shell colour.", invalid_choice="Choose one of the shell colours."
        )
        self.fields["camera"].error_messages.update(
            required="Choose a camera.", invalid_choice="Choose one of the cameras."
        )
        self.fields["lidar"].error_messages["invalid_choice"] = "Choose a lidar, or no lidar."
        self.sensors_locked = bool(self.instance.pk) and self.instance.rl_models.exists()
        if self.sensors_locked:
            for field in ("camera", "lidar"):
                self.fields[field].disabled = True
                self.fields[field].help_text = (
                    "Locked: models were trained on these sensors, and a model only reads the "
                    "sensors it learnt with. Build a new vehicle to try other sensors."
                )

    def clean_name(self) -> str:
        name = self.cleaned_data["name"].strip()
        others = Vehicle.objects.filter(owner=self.owner).exclude(pk=self.instance.pk)
        if others.filter(name__iexact=name).exists():
            raise forms.ValidationError(
                f"You already have a vehicle named “{name}”; choose another name."
            )
        return name


class RewardValidationForm(RacerWords, forms.Form):
    """What the editor's Validate button sends: the code and the track to try it on."""

    source = forms.CharField(
        strip=False,
        max_length=MAX_SOURCE_SIZE,
        error_messages={
            "required": "Write a reward function first.",
            "max_length": f"A reward function is at most {MAX_SOURCE_SIZE:,} characters long.",
        },
    )
    track = forms.ModelChoiceField(
        queryset=Track.objects.all(),
        to_field_name="name",
        error_messages={"required": "Choose a track.", "invalid_choice": "Choose a listed track."},
    )

    def first_error(self) -> str:
        return next(iter(self.errors.values()))[0]


class RewardFunctionForm(RewardValidationForm):
    """Save the editor's code in the racer's library: a name, the code, and the track its
    samples are taken from (the editor's "Try it on")."""

    name = forms.CharField(
        label="Name",
        max_length=64,
        required=False,  # the service says what is wrong with a name, in one place
        widget=forms.TextInput(attrs={"autocomplete": "off", "data-reward-name": ""}),
        help_text="Saved functions can be picked when you create a model.",
    )
    field_order = ["name", "source", "track"]


def _as_help(value: float) -> str:
    """A limit as a field's help shows it: 0.0003, 3e-5, 10."""
    return f"{value:g}".replace("e-0", "e-")


def range_help(low: float, high: float, default: float, *, note: str = "") -> str:
    """“Range 3-10, default 10 (DeepRacer's default).”: what a number field allows."""
    low_text, high_text = _as_help(low), _as_help(high)
    span = (
        f"{low_text} to {high_text}"
        if low < 0 or "e" in low_text + high_text
        else f"{low_text}-{high_text}"
    )
    return f"Range {span}, default {_as_help(default)} (DeepRacer's default).{note}"


def limit(field: forms.Field, low: float, high: float, step: float | str = "any") -> None:
    """Give a number input its range, so a racer sees the limits before submitting."""
    field.widget.attrs.update(min=_as_help(low), max=_as_help(high), step=step)


RANDOMISATION_HELP = (
    f"Each episode in a scene of its own ({randomisation_ranges.SUMMARY}), as DeepRacer for "
    "Cloud's DR_ENABLE_DOMAIN_RANDOMIZATION: a model that copes with scenes it has not seen."
)


class TrackLineForm(RacerWords, forms.Form):
    """Which of a track's racing lines the track page shows: its direction and the margin kept
    inside the borders (read from the query, so a line has its own address)."""

    direction = forms.ChoiceField(
        error_messages={"invalid_choice": "Choose a direction this track is driven in."}
    )
    margin = forms.TypedChoiceField(
        label="Margin inside the borders",
        coerce=int,
        choices=[(cm, f"{cm} cm") for cm in TrackLine.MARGINS_CM],
        help_text="Beyond half the car's width: room for a model that strays from the line.",
        error_messages={
            "invalid_choice": "Choose a margin of "
            + ", ".join(str(cm) for cm in TrackLine.MARGINS_CM[:-1])
            + f" or {TrackLine.MARGINS_CM[-1]} cm."
        },
    )

    def __init__(self, data, *, track: Track) -> None:
        data = {"direction": track.default_direction, "margin": "0", **data.dict()}
        super().__init__(data)
        self.fields["direction"].choices = [
            (direction, "Clockwise" if direction == "clockwise" else "Counter-clockwise")
            for direction in track.direction_values
        ]


class RaceConditionFields(RacerWords, forms.Form):
    """A race's boxes and bot cars, defined once: the create-model and evaluation pages train and
    evaluate under the limits an event's (``racing.forms``) races are held under. The limits and
    defaults are the simulator's (``simulator.config``), which are DeepRacer's: 3 boxes or bot
    cars, bots at 0.2 m/s (deepracer-simapp bundle/markov/agent_ctrl/bot_cars_agent_ctrl.py:39,
    and DeepRacer for Cloud's DR_H2B_BOT_CAR_SPEED)."""

    box_count = forms.IntegerField(
        label="Boxes",
        min_value=1,
        max_value=sim.MAX_OBJECTS,
        initial=sim.Objects.count,
        required=False,
        help_text=range_help(1, sim.MAX_OBJECTS, sim.Objects.count),
    )
    box_randomize = forms.BooleanField(label="New box positions every episode", required=False)
    bot_count = forms.IntegerField(
        label="Bot cars",
        min_value=1,
        max_value=sim.MAX_OBJECTS,
        initial=sim.Bots.count,
        required=False,
        help_text=range_help(1, sim.MAX_OBJECTS, sim.Bots.count),
    )
    bot_speed = forms.FloatField(
        label="Bot car speed [m/s]",
        min_value=sim.BOT_SPEED_RANGE[0],
        max_value=sim.BOT_SPEED_RANGE[1],
        initial=sim.Bots.speed,
        required=False,
        widget=forms.NumberInput(attrs={"step": "0.1"}),
        help_text=range_help(*sim.BOT_SPEED_RANGE, sim.Bots.speed),
    )
    bot_lane_changes = forms.BooleanField(label="Bot cars change lanes", required=False)

    @staticmethod
    def conditions_shown(boxes: dict | None, bots: dict | None) -> dict:
        """A saved race's boxes and bots (kept as JSON) as these fields' initial values."""
        boxes, bots = boxes or {}, bots or {}
        shown = {
            "box_count": boxes.get("count"),
            "box_randomize": boxes.get("randomize"),
            "bot_count": bots.get("count"),
            "bot_speed": bots.get("speed"),
            "bot_lane_changes": bots.get("lane_changes"),
        }
        return {name: value for name, value in shown.items() if value is not None}

    def boxes(self) -> dict:
        """The boxes as the simulator takes them; a count left out is the default."""
        data = self.cleaned_data
        count = data.get("box_count")
        return {
            "count": sim.Objects.count if count is None else count,
            "randomize": bool(data.get("box_randomize")),
        }

    def bots(self) -> dict:
        """The bot cars as the simulator takes them; what is left out is the default."""
        data = self.cleaned_data
        count, speed = data.get("bot_count"), data.get("bot_speed")
        return {
            "count": sim.Bots.count if count is None else count,
            "speed": sim.Bots.speed if speed is None else speed,
            "lane_changes": bool(data.get("bot_lane_changes")),
        }


class TrackAndRaceFields(RaceConditionFields):
    """Where and how the car races: the fields the create-model and evaluation pages share."""

    track = forms.ModelChoiceField(
        queryset=Track.objects.all(),
        to_field_name="name",
        empty_label=None,
        widget=forms.RadioSelect,
    )
    direction = forms.ChoiceField(
        choices=[("counterclockwise", "Counter-clockwise"), ("clockwise", "Clockwise")]
    )
    race_type = forms.ChoiceField(
        choices=RaceType.choices, widget=forms.RadioSelect, initial=RaceType.TIME_TRIAL
    )

    field_order = ["track", "direction", "race_type"]
    PLACES = {"boxes": "box_count", "bots": "bot_count"}  # where a setting's error shows

    def race_settings(self) -> dict:
        data = self.cleaned_data
        return {
            "track": data["track"].name,
            "direction": data["direction"],
            "race_type": data["race_type"],
            "boxes": self.boxes(),
            "bots": self.bots(),
        }

    def add_setting_errors(self, errors: dict[str, str]) -> None:
        """Put ``configuration.Invalid`` errors on the fields they concern."""
        for setting, message in errors.items():
            field = self.field_for(setting)
            self.add_error(field if field in self.fields else None, message)

    def field_for(self, setting: str) -> str | None:
        return self.PLACES.get(setting, setting)


class ModelCreateForm(TrackAndRaceFields):
    """The create-model page: each field as a racer fills it in. The settings are checked as a
    whole by ``training.configuration``; its errors come back onto these fields."""

    name = forms.CharField(max_length=64, help_text="1 to 64 letters, digits and hyphens.")
    description = forms.CharField(
        max_length=255,
        required=False,
        widget=forms.Textarea(attrs={"rows": 2}),
        help_text="Optional, up to 255 characters.",
    )
    field_order = ["name", "description", "track", "direction", "race_type"]
    domain_randomisation = forms.BooleanField(
        label="Domain randomisation",
        required=False,
        help_text=RANDOMISATION_HELP + " Off by default, as in DeepRacer.",
    )
    vehicle = forms.ModelChoiceField(
        queryset=Vehicle.objects.none(),
        required=False,
        empty_label="No vehicle: choose sensors below",
        help_text="A vehicle from your garage brings its sensors.",
    )
    camera = forms.ChoiceField(
        choices=Vehicle.Camera.choices,
        widget=forms.RadioSelect,
        initial=Vehicle.Camera.FRONT_FACING_CAMERA,
    )
    lidar = forms.ChoiceField(
        choices=Vehicle.Lidar.choices, required=False, widget=forms.RadioSelect, initial=""
    )
    camera_lens = forms.ChoiceField(
        label="Camera lens",
        choices=CameraLens.choices,
        required=False,
        widget=forms.RadioSelect,
        initial=CameraLens.SIMULATOR,
        help_text="DeepRacer's console trained with its simulated camera; choose the wide lens "
        "to train for the physical car's camera.",
        error_messages={
            "invalid_choice": "Choose DeepRacer's simulated camera or the car's wide lens."
        },
    )
    network = forms.ChoiceField(
        choices=Network.choices, widget=forms.RadioSelect, initial=Network.SHALLOW
    )
    action_space_type = forms.ChoiceField(
        choices=[("discrete", "Discrete"), ("continuous", "Continuous")],
        widget=forms.RadioSelect,
        initial="discrete",
    )
    actions = forms.CharField(
        required=False, widget=forms.HiddenInput, help_text="The discrete actions, as JSON."
    )
    steering_low = forms.FloatField(
        label="Lowest steering angle [°]",
        initial=-30,
        required=False,
        help_text=range_help(-30, 30, -30),
    )
    steering_high = forms.FloatField(
        label="Highest steering angle [°]",
        initial=30,
        required=False,
        help_text=range_help(-30, 30, 30),
    )
    speed_low = forms.FloatField(
        label="Lowest speed [m/s]",
        initial=1.0,
        required=False,
        help_text=range_help(*sim.SPEED_RANGE, 1),
    )
    speed_high = forms.FloatField(
        label="Highest speed [m/s]",
        initial=2.0,
        required=False,
        help_text=range_help(*sim.SPEED_RANGE, 2),
    )
    algorithm = forms.ChoiceField(
        choices=Algorithm.choices, widget=forms.RadioSelect, initial=Algorithm.PPO
    )
    max_minutes = forms.IntegerField(label="Maximum training time [min]", initial=60)
    best_checkpoint_by = forms.ChoiceField(
        label="Best checkpoint by",
        choices=BestCheckpointBy.choices,
        required=False,
        initial=BestCheckpointBy.PROGRESS,
        help_text="After each policy update a few evaluation episodes drive the new checkpoint; "
        "the best is the one whose episodes went furthest on average (DeepRacer's), earned the "
        "most reward, or lapped fastest (an unfinished lap counts 999.999 s). DeepRacer for "
        "Cloud's DR_TRAIN_BEST_MODEL_METRIC.",
    )
    evaluation_trials = forms.IntegerField(
        label="Evaluation episodes a checkpoint",
        initial=EVALUATION_TRIALS,
        required=False,
        help_text="Each new checkpoint drives this many episodes from starts spread round the "
        "track, to pick the best; more make a surer pick, at more of the machine's time. "
        + range_help(
            *EVALUATION_TRIALS_RANGE,
            EVALUATION_TRIALS,
            note=" DeepRacer for Cloud's DR_TRAIN_MIN_EVAL_TRIALS.",
        ),
    )
    cloned_checkpoint = forms.ChoiceField(
        label="Start from",
        choices=EvaluationJob.Checkpoint.choices,
        required=False,
        initial=EvaluationJob.Checkpoint.BEST,
        widget=forms.RadioSelect,
        help_text="Which of its source's checkpoints the clone's training starts from.",
    )
    workers = forms.IntegerField(
        label="Simulations at once",
        initial=1,
        help_text=range_help(
            1, configuration.MAX_WORKERS, 1, note=" Each extra track needs one more."
        ),
    )
    extra_tracks = forms.ModelMultipleChoiceField(
        queryset=Track.objects.all(),
        to_field_name="name",
        required=False,
        help_text="Train on more tracks at once: one more simulation each.",
    )
    reward_function = forms.CharField(strip=False, widget=forms.Textarea)

    # What a clone keeps from its source, since its weights are made for them; the number of
    # discrete actions too (the page's table offers no adding or removing).
    KEPT_BY_A_CLONE = {
        "vehicle": "sensors",
        "camera": "sensors",
        "lidar": "sensors",
        "network": "network",
        "algorithm": "training algorithm",
        "action_space_type": "kind of action space",
    }

    def __init__(self, *args, owner, source=None, **kwargs) -> None:
        """``source``: the model this one is a clone of, if it is one."""
        super().__init__(*args, **kwargs)
        self.owner = owner
        self.source = source
        self.action_errors: list[dict] = []  # the discrete action table's bad cells
        self.fields["vehicle"].queryset = Vehicle.objects.filter(owner=owner)
        for algorithm, settings in hyperparameters.SETTINGS.items():
            for setting in settings:
                self.fields[f"{algorithm}__{setting.name}"] = self._hyperparameter_field(setting)
        for name in ("steering_low", "steering_high"):
            limit(self.fields[name], -sim.MAX_STEERING, sim.MAX_STEERING, 1)
        for name in ("speed_low", "speed_high"):
            limit(self.fields[name], *sim.SPEED_RANGE, 0.1)
        self._limit_time(selectors.allowance_for(racer=owner).minutes_left)
        limit(self.fields["workers"], 1, configuration.MAX_WORKERS, 1)
        limit(self.fields["evaluation_trials"], *EVALUATION_TRIALS_RANGE, 1)
        if source is not None:
            self._lock_what_a_clone_keeps()
            if checkpoints := selectors.model_checkpoint_choices(model=source):
                self.fields["cloned_checkpoint"].choices = [(c.which, c.label) for c in checkpoints]

    @staticmethod
    def _hyperparameter_field(setting: hyperparameters.Setting) -> forms.Field:
        if setting.choices:
            shown = {c: hyperparameters.LABELS.get(c, str(c)) for c in setting.choices}
            field = forms.TypedChoiceField(
                choices=list(shown.items()),
                coerce=type(setting.default),
                initial=setting.default,
            )
            field.help_text = (
                f"Fixed at {shown[setting.default]}, as in DeepRacer."
                if len(setting.choices) == 1
                else f"One of {', '.join(shown.values())}; default {shown[setting.default]} "
                "(DeepRacer's default)."
            )
        else:
            field = forms.FloatField(initial=setting.default)
            limit(field, setting.low, setting.high, 1 if setting.integer else "any")
            field.help_text = (
                f"Fixed at {_as_help(setting.low)}, as in DeepRacer."
                if setting.low == setting.high
                else range_help(setting.low, setting.high, setting.default)
            )
        field.label = setting.label
        field.required = False
        return field

    def _limit_time(self, minutes_left: int) -> None:
        low, high = configuration.MINUTES
        field = self.fields["max_minutes"]
        limit(field, low, max(low, min(high, minutes_left)), 1)
        field.help_text = range_help(
            low, high, 60, note=f" You have {minutes_left} training minutes left this month."
        )

    def _lock_what_a_clone_keeps(self) -> None:
        """Show what a clone keeps locked. A browser sends nothing for a disabled input, so the
        source's values fill in for them; a change sent anyway is refused by
        ``configuration``, which names what a clone keeps."""
        if self.is_bound:
            self.data = self.data.copy()
            for name in self.KEPT_BY_A_CLONE:
                if name not in self.data:
                    value = self.initial.get(name)
                    self.data[name] = "" if value is None else value
        for name, what in self.KEPT_BY_A_CLONE.items():
            field = self.fields[name]
            field.widget.attrs["disabled"] = True
            field.help_text = (
                f"Locked: a clone keeps {self.source.name}'s {what}, which its weights were "
                "trained for."
            )

    @staticmethod
    def initial_from(model: configuration.ModelSettings) -> dict:
        """The page filled in with a model's settings: what Clone starts from. The settings the
        page takes as they are saved are shown as they are (``configuration.SETTINGS``); a
        clone's own start is chosen anew."""
        draft = model.draft()
        initial = {
            name: value
            for name, value in draft.items()
            if name in ModelCreateForm.base_fields and name != "cloned_checkpoint"
        }
        initial.update(
            name=f"{model.name}-clone"[:64],
            vehicle=model.vehicle.pk if model.vehicle else None,
            camera=next((s for s in model.sensors if s in Vehicle.Camera.values), ""),
            lidar=next((s for s in model.sensors if s in ("LIDAR", "SECTOR_LIDAR")), ""),
            action_space_type=model.action_space_type,
            **RaceConditionFields.conditions_shown(model.boxes, model.bots),
        )
        if model.action_space_type == "discrete":
            initial["actions"] = json.dumps(model.action_space)
        else:
            space = model.action_space
            initial.update(
                steering_low=space["steering_angle"]["low"],
                steering_high=space["steering_angle"]["high"],
                speed_low=space["speed"]["low"],
                speed_high=space["speed"]["high"],
            )
        for name, value in model.hyperparameters.items():
            initial[f"{model.algorithm}__{name}"] = hyperparameters.spelled(
                model.algorithm, name, value
            )
        return initial

    def hyperparameter_fields(self, algorithm: str) -> list:
        return [self[f"{algorithm}__{s.name}"] for s in hyperparameters.SETTINGS[algorithm]]

    def settings(self) -> configuration.Draft:
        """The model's settings as the racer gave them, for ``configuration.check``."""
        data = self.cleaned_data
        vehicle = data.get("vehicle")
        sensors = (
            vehicle.sensors
            if vehicle
            else [data["camera"]] + ([data["lidar"]] if data.get("lidar") else [])
        )
        if data["action_space_type"] == "continuous":
            action_space = {
                "steering_angle": {
                    "low": data.get("steering_low"),
                    "high": data.get("steering_high"),
                },
                "speed": {"low": data.get("speed_low"), "high": data.get("speed_high")},
            }
        else:
            try:
                action_space = json.loads(data.get("actions") or "[]")
            except json.JSONDecodeError:
                action_space = "unreadable"
        algorithm = data["algorithm"]
        draft: configuration.Draft = {
            # the settings the page takes as they are saved (blank: check's default)
            **{name: data.get(name) for name in configuration.SETTINGS if name in data},
            **self.race_settings(),
            "sensors": sensors,
            "action_space": action_space,
            "hyperparameters": {
                # DeepRacer's keys this console keeps without using: a clone keeps its source's
                **self._kept_hyperparameters(algorithm),
                **{
                    s.name: data.get(f"{algorithm}__{s.name}")
                    for s in hyperparameters.SETTINGS.get(algorithm, ())
                    if data.get(f"{algorithm}__{s.name}") not in (None, "")
                },
            },
            "extra_tracks": [track.name for track in data.get("extra_tracks") or []],
        }
        if self.source is None:  # only a clone starts from a checkpoint (blank: the best)
            draft.pop("cloned_checkpoint", None)
        return draft

    def _kept_hyperparameters(self, algorithm: str) -> dict:
        if self.source is None or self.source.algorithm != algorithm:
            return {}
        kept = hyperparameters.kept_settings(algorithm)
        return {k: v for k, v in self.source.hyperparameters.items() if k in kept}

    PLACES = {
        **TrackAndRaceFields.PLACES,
        "sensors": "camera",
        "action_space": "actions",
        "action_space.steering_angle.low": "steering_low",
        "action_space.steering_angle.high": "steering_high",
        "action_space.speed.low": "speed_low",
        "action_space.speed.high": "speed_high",
        "cloned_from": None,
    }
    ACTION_CELL = re.compile(r"^action_space\.(\d+)(?:\.(steering_angle|speed))?$")

    def field_for(self, setting: str) -> str | None:
        if setting.startswith("hyperparameters."):
            return f"{self.cleaned_data.get('algorithm', '')}__{setting.split('.', 1)[1]}"
        if self.ACTION_CELL.match(setting):
            return "actions"
        field = super().field_for(setting)
        if field == "actions" and self.cleaned_data.get("action_space_type") == "continuous":
            return "action_space_type"
        return field

    def add_setting_errors(self, errors: dict[str, str]) -> None:
        """As for every field; an action's error also marks its cells in the action table."""
        for setting, message in errors.items():
            cell = self.ACTION_CELL.match(setting)
            if cell:
                columns = [cell[2]] if cell[2] else ["steering_angle", "speed"]
                self.action_errors.append(
                    {"index": int(cell[1]), "columns": columns, "message": message}
                )
        super().add_setting_errors(errors)

    def action_table_errors(self) -> list[str]:
        """The action table's errors that no single action's cells show."""
        in_cells = {error["message"] for error in self.action_errors}
        return [error for error in self.errors.get("actions", []) if error not in in_cells]

    def sections_with_errors(self) -> "list[Section]":
        """The page's sections that hold an error, in the page's order: what the summary at
        the top links to."""
        fields = {name for name, errors in self.errors.items() if errors and name != "__all__"}
        return [section for section in SECTIONS if fields & set(section.fields(self))]


@dataclass(frozen=True)
class Section:
    """One section of the create-model page: its anchor, its title, the fields it holds (the
    hyperparameter fields, ``<algorithm>__<key>``, by ``prefixed``)."""

    anchor: str
    title: str
    names: tuple[str, ...]
    prefixed: bool = False

    def fields(self, form: forms.Form) -> list[str]:
        return [
            name for name in form.fields if name in self.names or (self.prefixed and "__" in name)
        ]


SECTIONS = (
    Section("section-name", "Name", ("name", "description", "cloned_checkpoint")),
    Section("section-track", "Track", ("track", "direction", "domain_randomisation")),
    Section(
        "section-race-type",
        "Race type",
        ("race_type", "box_count", "box_randomize", "bot_count", "bot_speed", "bot_lane_changes"),
    ),
    Section(
        "section-car",
        "Car: sensors and network",
        ("vehicle", "camera", "lidar", "camera_lens", "network"),
    ),
    Section(
        "section-action-space",
        "Action space",
        (
            "action_space_type",
            "actions",
            "steering_low",
            "steering_high",
            "speed_low",
            "speed_high",
        ),
    ),
    Section(
        "section-algorithm", "Training algorithm and hyperparameters", ("algorithm",), prefixed=True
    ),
    Section(
        "section-stop",
        "Stop condition and workers",
        ("max_minutes", "workers", "extra_tracks", "best_checkpoint_by", "evaluation_trials"),
    ),
    Section("section-reward-function", "Reward function", ("reward_function",)),
)


@dataclass(frozen=True)
class SettingShown:
    """One row of a model's training settings as its page shows them: the create form's label,
    the value as the form spells it, DeepRacer's key."""

    label: str
    value: str
    key: str


def training_settings_shown(
    *, algorithm: str, stored: dict, max_minutes: int
) -> tuple[list[SettingShown], list[SettingShown]]:
    """(the settings a model trains with, DeepRacer's others that it keeps without using),
    labelled as the create form labels them, in its order."""

    def shown(name: str, value) -> SettingShown:
        each = hyperparameters.setting(algorithm, name)
        label = each.label if each else name
        if isinstance(value, float):
            text = _as_help(value)
        else:
            text = hyperparameters.LABELS.get(value, str(value))
        return SettingShown(label, text, name)

    order = [s.name for s in hyperparameters.SETTINGS.get(algorithm, ())]
    used = [shown(name, stored[name]) for name in order if name in stored]
    minutes = ModelCreateForm.base_fields["max_minutes"]
    used.append(SettingShown(str(minutes.label), str(max_minutes), ""))
    others = [shown(name, value) for name, value in stored.items() if name not in order]
    return used, others


class EvaluationForm(TrackAndRaceFields):
    """The Evaluate page: the track and race rules; checked by
    ``configuration.check_evaluation``."""

    trials = forms.TypedChoiceField(
        choices=[(n, f"{n} trials") for n in (3, 4, 5)],
        coerce=int,
        initial=3,
        help_text="Each trial is one lap.",
    )
    continuous_laps = forms.BooleanField(
        label="Continuous laps",
        required=False,
        help_text="The car drives its trials lap after lap without stopping, as in a race.",
    )
    off_track_penalty = forms.FloatField(
        label="Off-track penalty [s]",
        min_value=0,
        max_value=10,
        initial=2.0,
        widget=forms.NumberInput(attrs={"step": "0.1"}),
        help_text="The car waits this long after leaving the track, then goes back on it. "
        + range_help(0, 10, 2),
    )
    crash_penalty = forms.FloatField(
        label="Crash penalty [s]",
        min_value=0,
        max_value=10,
        initial=5.0,
        widget=forms.NumberInput(attrs={"step": "0.1"}),
        help_text="The same, after hitting a box or a bot car. " + range_help(0, 10, 5),
    )
    max_resets = forms.IntegerField(
        label="Resets allowed",
        min_value=0,
        max_value=sim.MAX_RESETS,
        initial=sim.DEFAULT_MAX_RESETS,
        required=False,
        help_text="Each time the car leaves the track, crashes, turns back or gets stuck, it is "
        "put back on the track; after this many, its trial ends where it is. 0 ends it at the "
        f"first; empty, never. Range 0-{sim.MAX_RESETS:,}, default {sim.DEFAULT_MAX_RESETS} "
        "(DeepRacer for Cloud's DR_EVAL_MAX_RESETS).",
    )
    domain_randomisation = forms.BooleanField(
        label="Randomised scenes",
        required=False,
        help_text=RANDOMISATION_HELP.replace("Each episode", "Each trial")
        + " Off: the plain scene, whatever the model trained in.",
    )
    checkpoint = forms.ChoiceField(
        choices=EvaluationJob.Checkpoint.choices,
        initial=EvaluationJob.Checkpoint.BEST,
        widget=forms.RadioSelect,
    )

    def __init__(
        self, *args, checkpoints: list[selectors.CheckpointChoice] | None = None, **kwargs
    ) -> None:
        """``checkpoints``: the model's, to name each choice by its iteration."""
        super().__init__(*args, **kwargs)
        if checkpoints:
            self.fields["checkpoint"].choices = [(c.which, c.label) for c in checkpoints]

    def settings(self) -> dict:
        data = self.cleaned_data
        return {
            **self.race_settings(),
            **{
                name: data[name]
                for name in (
                    "trials",
                    "continuous_laps",
                    "off_track_penalty",
                    "crash_penalty",
                    "max_resets",
                    "checkpoint",
                    "domain_randomisation",
                )
            },
        }
