import json

from django import forms

from training import configuration, hyperparameters, imports
from training.models import Algorithm, EvaluationJob, Network, RaceType, Track, Vehicle
from training.rewards import MAX_SOURCE_SIZE


class ModelImportForm(forms.Form):
    """The name first (checked before the archive is read, and in the browser as it is typed),
    then the archive, or the one the racer uploaded to an attempt that had to be corrected
    (``kept_upload``, named by the hidden ``kept`` token)."""

    name = forms.CharField(
        max_length=64, required=False,
        help_text="Leave empty to keep the archive's name. Letters, digits and hyphens.",
    )  # fmt: skip
    archive = forms.FileField(
        label="Archive (.tar.gz)", required=False,
        help_text="A Pitlane virtual model, or a model downloaded from DeepRacer.",
        widget=forms.FileInput(attrs={"accept": ".tar.gz,.tgz,.tar,application/gzip"}),
    )  # fmt: skip
    kept = forms.CharField(required=False, widget=forms.HiddenInput)

    def __init__(self, *args, owner, kept: imports.KeptUpload | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.owner = owner
        self.kept_upload = kept

    def clean_name(self) -> str:
        name = self.cleaned_data["name"].strip()
        if name and (problem := configuration.name_problem(name, owner=self.owner)):
            raise forms.ValidationError(problem)
        return name

    def clean_archive(self):
        archive = self.cleaned_data["archive"]
        if archive is None:
            if self.kept_upload is None:
                raise forms.ValidationError(
                    "Choose the model's archive: a virtualmodel-<name>.tar.gz or a model "
                    "downloaded from DeepRacer."
                )
            return None
        if archive.size > imports.MAX_ARCHIVE:
            raise forms.ValidationError(f"The archive is over {imports.size(imports.MAX_ARCHIVE)}.")
        return archive

    def keep(self, kept: imports.KeptUpload | None) -> None:
        """Show ``kept`` (or nothing) as the archive the next attempt uses."""
        self.kept_upload = kept
        self.data = self.data.copy()
        self.data["kept"] = kept.token if kept else ""


class VehicleForm(forms.ModelForm):
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
        self.fields["shell_colour"].error_messages["required"] = "Choose a shell colour."
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


class RewardValidationForm(forms.Form):
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


class TrackAndRaceFields(forms.Form):
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
    box_count = forms.IntegerField(
        label="Boxes", min_value=1, max_value=6, initial=3, required=False
    )
    box_randomize = forms.BooleanField(label="New box positions every episode", required=False)
    bot_count = forms.IntegerField(
        label="Bot cars", min_value=1, max_value=6, initial=3, required=False
    )
    bot_speed = forms.FloatField(
        label="Bot speed [m/s]", min_value=0.2, max_value=6, initial=0.5, required=False
    )
    bot_lane_changes = forms.BooleanField(label="Bots change lanes", required=False)

    PLACES = {"boxes": "box_count", "bots": "bot_count"}  # where a setting's error shows

    def race_settings(self) -> dict:
        data = self.cleaned_data
        return {
            "track": data["track"].name,
            "direction": data["direction"],
            "race_type": data["race_type"],
            "boxes": {"count": data.get("box_count") or 3, "randomize": data.get("box_randomize")},
            "bots": {
                "count": data.get("bot_count") or 3,
                "speed": data.get("bot_speed") or 0.5,
                "lane_changes": data.get("bot_lane_changes"),
            },
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

    name = forms.CharField(max_length=64, help_text="Letters, digits and hyphens.")
    description = forms.CharField(
        max_length=255, required=False, widget=forms.Textarea(attrs={"rows": 2})
    )
    field_order = ["name", "description", "track", "direction", "race_type"]
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
    steering_low = forms.FloatField(initial=-30, required=False)
    steering_high = forms.FloatField(initial=30, required=False)
    speed_low = forms.FloatField(initial=1.0, required=False)
    speed_high = forms.FloatField(initial=2.0, required=False)
    algorithm = forms.ChoiceField(
        choices=Algorithm.choices, widget=forms.RadioSelect, initial=Algorithm.PPO
    )
    max_minutes = forms.IntegerField(label="Maximum training time [min]", initial=60)
    workers = forms.IntegerField(label="Simulation workers", initial=1)
    extra_tracks = forms.ModelMultipleChoiceField(
        queryset=Track.objects.all(),
        to_field_name="name",
        required=False,
        help_text="Train on more tracks at once: one extra simulation worker each.",
    )
    reward_function = forms.CharField(strip=False, widget=forms.Textarea)

    def __init__(self, *args, owner, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.owner = owner
        self.fields["vehicle"].queryset = Vehicle.objects.filter(owner=owner)
        for algorithm, settings in hyperparameters.SETTINGS.items():
            for setting in settings:
                name = f"{algorithm}__{setting.name}"
                if setting.choices:
                    field = forms.TypedChoiceField(
                        choices=[(c, c) for c in setting.choices],
                        coerce=type(setting.default),
                        initial=setting.default,
                    )
                else:
                    field = forms.FloatField(initial=setting.default)
                field.label = setting.label
                field.required = False
                self.fields[name] = field

    @staticmethod
    def initial_from(model) -> dict:
        """The page filled in with ``model``'s settings: what Clone starts from."""
        initial = {
            "name": f"{model.name}-clone"[:64],
            "description": model.description,
            "track": model.track.name,
            "direction": model.direction,
            "race_type": model.race_type,
            "camera": next((s for s in model.sensors if s in Vehicle.Camera.values), ""),
            "lidar": next((s for s in model.sensors if s in ("LIDAR", "SECTOR_LIDAR")), ""),
            "vehicle": model.vehicle_id,
            "network": model.network,
            "action_space_type": model.action_space_type,
            "algorithm": model.algorithm,
            "max_minutes": model.max_minutes,
            "workers": model.workers,
            "extra_tracks": list(model.extra_tracks),
            "reward_function": model.reward_function,
        }
        if model.boxes:
            initial.update(box_count=model.boxes.get("count"),
                           box_randomize=model.boxes.get("randomize"))  # fmt: skip
        if model.bots:
            initial.update(bot_count=model.bots.get("count"), bot_speed=model.bots.get("speed"),
                           bot_lane_changes=model.bots.get("lane_changes"))  # fmt: skip
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
            initial[f"{model.algorithm}__{name}"] = value
        return initial

    def hyperparameter_fields(self, algorithm: str) -> list:
        return [self[f"{algorithm}__{s.name}"] for s in hyperparameters.SETTINGS[algorithm]]

    def settings(self) -> dict:
        """The model's settings, in ``training.configuration``'s vocabulary."""
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
                action_space = json.loads(data.get("actions") or "null")
            except json.JSONDecodeError:
                action_space = "unreadable"
        algorithm = data["algorithm"]
        return {
            "name": data["name"],
            "description": data.get("description", ""),
            **self.race_settings(),
            "sensors": sensors,
            "vehicle": vehicle,
            "network": data["network"],
            "action_space": action_space,
            "algorithm": algorithm,
            "hyperparameters": {
                s.name: data.get(f"{algorithm}__{s.name}")
                for s in hyperparameters.SETTINGS.get(algorithm, ())
                if data.get(f"{algorithm}__{s.name}") not in (None, "")
            },
            "max_minutes": data["max_minutes"],
            "workers": data["workers"],
            "extra_tracks": [track.name for track in data.get("extra_tracks") or []],
            "reward_function": data["reward_function"],
        }

    PLACES = {
        **TrackAndRaceFields.PLACES,
        "sensors": "camera",
        "action_space": "actions",
        "cloned_from": None,
    }

    def field_for(self, setting: str) -> str | None:
        if setting.startswith("hyperparameters."):
            return f"{self.cleaned_data.get('algorithm', '')}__{setting.split('.', 1)[1]}"
        field = super().field_for(setting)
        if field == "actions" and self.cleaned_data.get("action_space_type") == "continuous":
            return "steering_low"
        return field


class EvaluationForm(TrackAndRaceFields):
    """The Evaluate page: the track and race rules; checked by
    ``configuration.check_evaluation``."""

    trials = forms.TypedChoiceField(
        choices=[(n, f"{n} trials") for n in (3, 4, 5)], coerce=int, initial=3,
        help_text="Each trial is one lap.",
    )  # fmt: skip
    continuous_laps = forms.BooleanField(
        label="Continuous laps", required=False,
        help_text="The car drives its trials lap after lap without stopping, as in a race.",
    )  # fmt: skip
    off_track_penalty = forms.FloatField(
        label="Off-track penalty [s]", min_value=0, max_value=10, initial=2.0,
        help_text="The car waits this long after leaving the track, then goes back on it.",
    )  # fmt: skip
    crash_penalty = forms.FloatField(
        label="Crash penalty [s]", min_value=0, max_value=10, initial=5.0,
        help_text="The same, after hitting a box or a bot car.",
    )  # fmt: skip
    checkpoint = forms.ChoiceField(
        choices=EvaluationJob.Checkpoint.choices, initial=EvaluationJob.Checkpoint.BEST,
        widget=forms.RadioSelect,
    )  # fmt: skip

    def settings(self) -> dict:
        data = self.cleaned_data
        return {
            **self.race_settings(),
            **{name: data[name] for name in ("trials", "continuous_laps", "off_track_penalty",
                                             "crash_penalty", "checkpoint")},
        }  # fmt: skip
