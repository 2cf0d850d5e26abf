"""Forms of the league: submitting a model, and organising a community race."""

from __future__ import annotations

import re
import secrets
from datetime import timedelta

from django import forms
from django.core.exceptions import ValidationError
from django.utils import timezone

from common.forms import RacerWords
from common.time_zones import local_text
from racing import selectors, timing
from racing.models import MIN_LAP_S, Event, RaceType, RankingMethod
from training import selectors as training_selectors
from training.forms import RaceConditionFields
from training.models import EvaluationJob, RLModel, Track

LOCAL = "%Y-%m-%dT%H:%M"  # what <input type="datetime-local"> sends
RACE_LENGTH = timedelta(days=7)  # a new community race closes a week after it opens
FORM_TOKEN = re.compile(r"[A-Za-z0-9_-]{32,43}")  # secrets.token_urlsafe(32) makes 43


def _choose_the_only(field: forms.ModelChoiceField) -> None:
    """A list of one is chosen already: a racer with one ready model need not pick it."""
    found = list(field.queryset.values_list("pk", flat=True)[:2])
    if len(found) == 1:
        field.initial = found[0]


class SubmissionForm(RacerWords, forms.Form):
    """A racer's ready model and an open event they may enter."""

    event = forms.ModelChoiceField(
        queryset=Event.objects.none(),
        empty_label="Choose an event",
        error_messages={"invalid_choice": "Choose one of the open events listed."},
    )
    model = forms.ModelChoiceField(
        queryset=RLModel.objects.none(),
        empty_label="Choose a model",
        error_messages={"invalid_choice": "Choose one of your ready models."},
        help_text="Your ready models.",
    )
    checkpoint = forms.ChoiceField(
        choices=EvaluationJob.Checkpoint.choices,
        initial=EvaluationJob.Checkpoint.BEST,
        widget=forms.RadioSelect,
        required=False,
        help_text="Which of the model's checkpoints races: the best its training measured "
        "(by its best-checkpoint setting) or the last it saved.",
    )

    def __init__(self, *args, racer, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.racer = racer
        events = selectors.events_open_to(racer=racer)
        self.fields["event"].queryset = Event.objects.filter(pk__in=[e.pk for e in events])
        self.fields["event"].label_from_instance = _event_label
        self.fields["model"].queryset = selectors.models_ready_for(racer=racer)
        self.fields["model"].label_from_instance = _model_label
        _choose_the_only(self.fields["event"])
        _choose_the_only(self.fields["model"])

    def clean(self) -> dict:
        data = super().clean()
        if data.get("event") and data.get("model"):
            reason = selectors.submission_refusal(
                racer=self.racer, event=data["event"], model=data["model"]
            )
            if reason:
                raise ValidationError(reason)
        return data


def _model_label(model: RLModel) -> str:
    """A ready model by name, said to be untrained where it is (its entry would be refused);
    its last checkpoint from the jobs ``models_ready_for`` fetched with it."""
    saved = getattr(model, "saved_jobs", None)
    last = (saved[0].last_checkpoint if saved else "") if saved is not None else None
    if training_selectors.model_untrained(model=model, last_checkpoint=last):
        return f"{model.name} (Ready: {training_selectors.UNTRAINED})"
    return model.name


def _event_label(event: Event) -> str:
    rule = f"{event.get_race_type_display().lower()} on {event.track}"
    return f"{event.name} ({rule}, closes {local_text(event.closes_at)})"


# An event's race and rules, as the admin and a community race's organiser set them.
RACE_FIELDS = [
    "track",
    "direction",
    "race_type",
    "cars",
    "opens_at",
    "closes_at",
    "ranking_method",
    "laps_required",
    "laps_to_drive",
    "off_track_penalty_s",
    "crash_penalty_s",
    "max_off_tracks_per_lap",
    "submissions_per_racer",
]


class RaceObstaclesForm(RaceConditionFields, forms.ModelForm):
    """An event's boxes and bot cars as fields of their own (the model keeps them as JSON), with
    the limits a model trains under (``training.forms.RaceConditionFields``); those of the chosen
    race type are required: an event's rules are written out."""

    NEEDED = {
        RaceType.OBJECT_AVOIDANCE: {"box_count": "Say how many boxes the race has."},
        RaceType.HEAD_TO_BOT: {
            "bot_count": "Say how many bot cars the race has.",
            "bot_speed": "Say how fast the bot cars drive.",
        },
    }

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.initial.update(self.conditions_shown(self.instance.boxes, self.instance.bots))
        if "cars" in self.fields:  # left out: each model alone, as before the field existed
            self.fields["cars"].required = False
        if "min_lap_s" in self.fields:  # left out: the default shortest lap of a real car
            self.fields["min_lap_s"].required = False

    def clean_cars(self) -> int:
        return self.cleaned_data.get("cars") or 1

    def clean_min_lap_s(self) -> float:
        shortest = self.cleaned_data.get("min_lap_s")
        return MIN_LAP_S if shortest is None else shortest

    def clean(self) -> dict:
        data = super().clean()
        race_type = data.get("race_type")
        for name, message in self.NEEDED.get(race_type, {}).items():
            if data.get(name) is None and name not in self.errors:
                self.add_error(name, message)
        self.instance.boxes = self.boxes() if race_type == RaceType.OBJECT_AVOIDANCE else None
        self.instance.bots = self.bots() if race_type == RaceType.HEAD_TO_BOT else None
        return data


class CommunityRaceForm(RaceObstaclesForm):
    """A community race: a private event its organiser runs, entered by invitation. It opens
    now and closes in a week unless the organiser says otherwise (in their own time zone)."""

    track = forms.ModelChoiceField(
        queryset=Track.objects.all(),
        to_field_name="name",
        error_messages={
            "required": "Choose a track.",
            "invalid_choice": "Choose one of the tracks shown.",
        },
    )

    class Meta:
        model = Event
        fields = ["name", *RACE_FIELDS]
        widgets = {
            "opens_at": forms.DateTimeInput(attrs={"type": "datetime-local"}, format=LOCAL),
            "closes_at": forms.DateTimeInput(attrs={"type": "datetime-local"}, format=LOCAL),
        }
        help_texts = {
            "ranking_method": "The league's rule is the first; lower is better.",
            "opens_at": "In your time zone.",
            "closes_at": "In your time zone. The invitation works until then.",
        }

    form_token = forms.CharField(widget=forms.HiddenInput, required=False)

    def __init__(self, *args, organiser, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        # A one-time token per form shown: the same form sent twice creates one race.
        self.fields["form_token"].initial = secrets.token_urlsafe(32)
        self.stale = False
        name = self.add_prefix("form_token")
        if self.is_bound and not FORM_TOKEN.fullmatch(self.data.get(name) or ""):
            self.data = self.data.copy()
            self.data[name] = self.fields["form_token"].initial
            self.stale = True
        self.fields["ranking_method"].initial = RankingMethod.FIRST_CONSECUTIVE
        self.fields["track"].initial = Track.objects.values_list("name", flat=True).first()
        now = timezone.localtime().replace(second=0, microsecond=0)
        self.fields["opens_at"].initial = now
        self.fields["closes_at"].initial = now + RACE_LENGTH
        self.instance.organiser = organiser
        self.instance.public = False

    def clean(self) -> dict:
        data = super().clean()
        if self.stale:
            raise ValidationError(
                "This page was out of date: check the race below, then create it again."
            )
        return data

    def fields_for_service(self) -> dict:
        data = {name: self.cleaned_data[name] for name in self.Meta.fields}
        return {**data, "boxes": self.instance.boxes, "bots": self.instance.bots}


class TimedRunForm(RacerWords, forms.Form):
    """A real car about to be timed: whose it is (by racer name, never the login name, which
    sign-up promises nobody sees), the model it runs, and which car (by its number)."""

    racer = forms.CharField(
        label="Racer",
        max_length=64,
        help_text="Their racer name, as the leaderboard shows it: type a few letters to search.",
        widget=forms.TextInput(attrs={"autocomplete": "off", "data-racer-search": ""}),
    )
    model_name = forms.CharField(
        label="Model", max_length=64, help_text="The model loaded on the car, as it is known."
    )
    car = forms.CharField(
        label="Car number",
        max_length=64,
        help_text="The number on the car (its name, where it has no number).",
    )

    def __init__(self, *args, racers, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.racers = racers  # those this timekeeper may time (timing.racers_timed_by)

    def clean_racer(self):
        try:
            return timing.racer_named(name=self.cleaned_data["racer"], among=self.racers)
        except timing.TimingRefused as refused:
            raise ValidationError(str(refused)) from None

    def clean_car(self) -> str:
        return self.cleaned_data["car"].strip()


def _lap_seconds(label: str, help_text: str) -> forms.DecimalField:
    """A time within a lap [s], to the millisecond, no longer than a lap may be."""
    return forms.DecimalField(
        label=label,
        min_value=0,
        max_value=timing.MAX_LAP_MS // 1000,
        max_digits=9,
        decimal_places=3,
        required=False,
        help_text=help_text,
    )


class LapEditForm(RacerWords, forms.Form):
    """A timekeeper's edit of one run's laps (``racing.lap_edits``): strike a lap out, restore
    it, split it at a missed crossing, or add a lap at the end of a finished run."""

    ACTIONS = {
        "strike": "Strike the lap out",
        "restore": "Restore the lap",
        "split": "Split the lap at a missed crossing",
        "add": "Add a lap at the end",
    }
    action = forms.ChoiceField(choices=list(ACTIONS.items()), widget=forms.HiddenInput)
    lap = forms.IntegerField(label="Lap", min_value=1, max_value=32_767, required=False)
    first_s = _lap_seconds(
        "Its first part took [s]",
        "From the lap's start to the crossing you missed; its off-tracks stay with it.",
    )
    time_s = _lap_seconds(
        "Lap time [s]", "The time the car drove, off a stopwatch or a video; penalties are added."
    )
    off_tracks = forms.IntegerField(
        label="Off-tracks", min_value=0, max_value=timing.MAX_OFF_TRACKS, initial=0, required=False
    )

    def __init__(self, *args, submission, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.submission = submission

    def clean(self) -> dict:
        data = super().clean()
        action = data.get("action")
        if action in ("strike", "restore", "split"):
            number = data.get("lap")
            data["lap_row"] = self.submission.laps.filter(number=number).first()
            if number is None or data["lap_row"] is None:
                self.add_error("lap", "Choose one of the run's laps by its number.")
        if action == "split" and data.get("first_s") is None and "first_s" not in self.errors:
            self.add_error("first_s", "Say how long the lap's first part took, in seconds.")
        if action == "add" and data.get("time_s") is None and "time_s" not in self.errors:
            self.add_error("time_s", "Say the lap's time, in seconds.")
        for name in ("first_s", "time_s"):
            if data.get(name) is not None:
                data[name.replace("_s", "_ms")] = round(data[name] * 1000)
        return data


class LiveJoinForm(RacerWords, forms.Form):
    """A racer's place in a live race's queue: a ready model and its speed multiplier."""

    model = forms.ModelChoiceField(
        queryset=RLModel.objects.none(),
        empty_label="Choose a model",
        error_messages={"invalid_choice": "Choose one of your ready models."},
    )
    speed = forms.FloatField(
        label="Speed multiplier",
        initial=1.0,
        help_text="Your model's speeds times this during your turn.",
    )

    def __init__(self, *args, racer, session, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.fields["model"].queryset = selectors.models_ready_for(racer=racer)
        self.fields["model"].label_from_instance = _model_label
        _choose_the_only(self.fields["model"])
        speed = self.fields["speed"]
        speed.min_value, speed.max_value = session.min_speed, session.max_speed
        speed.widget.attrs.update(min=session.min_speed, max=session.max_speed, step=0.1)
        speed.help_text += f" From {session.min_speed:g} to {session.max_speed:g}."


class LiveSessionForm(RacerWords, forms.Form):
    """The facilitator's settings of a live race."""

    min_speed = forms.FloatField(
        label="Slowest speed multiplier", initial=0.5, min_value=0.1, max_value=2.0
    )
    max_speed = forms.FloatField(
        label="Fastest speed multiplier", initial=1.5, min_value=0.1, max_value=2.0
    )
    autolaunch = forms.BooleanField(
        label="Launch each turn as soon as the last one ends", required=False
    )

    def clean(self) -> dict:
        data = super().clean()
        if (
            data.get("min_speed")
            and data.get("max_speed")
            and data["min_speed"] > data["max_speed"]
        ):
            raise ValidationError("The slowest multiplier is above the fastest: swap them.")
        return data
