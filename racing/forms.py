"""Forms of the league: submitting a model, and organising a community race."""

from __future__ import annotations

from django import forms
from django.core.exceptions import ValidationError

from console.time_zones import local_text
from racing import selectors
from racing.models import Event, RaceType, RankingMethod
from training.models import RLModel

LOCAL = "%Y-%m-%dT%H:%M"  # what <input type="datetime-local"> sends


class SubmissionForm(forms.Form):
    """A racer's ready model and an open event they may enter."""

    event = forms.ModelChoiceField(
        queryset=Event.objects.none(), empty_label="Choose an event",
        error_messages={"invalid_choice": "Choose one of the open events listed."},
    )  # fmt: skip
    model = forms.ModelChoiceField(
        queryset=RLModel.objects.none(), empty_label="Choose a model",
        error_messages={"invalid_choice": "Choose one of your ready models."},
        help_text="Your ready models. The race drives its best checkpoint.",
    )  # fmt: skip

    def __init__(self, *args, racer, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.racer = racer
        events = selectors.events_open_to(racer=racer)
        self.fields["event"].queryset = Event.objects.filter(pk__in=[e.pk for e in events])
        self.fields["event"].label_from_instance = _event_label
        self.fields["model"].queryset = selectors.models_ready_for(racer=racer)

    def clean(self) -> dict:
        data = super().clean()
        if data.get("event") and data.get("model"):
            reason = selectors.submission_refusal(
                racer=self.racer, event=data["event"], model=data["model"]
            )
            if reason:
                raise ValidationError(reason)
        return data


def _event_label(event: Event) -> str:
    rule = f"{event.get_race_type_display().lower()} on {event.track}"
    return f"{event.name} ({rule}, closes {local_text(event.closes_at)})"


class CommunityRaceForm(forms.ModelForm):
    """A community race: a private event its organiser runs, entered by invitation."""

    obstacles = forms.IntegerField(
        label="Boxes or bot cars", min_value=1, max_value=6, initial=3, required=False,
        help_text="For object avoidance (boxes) and head-to-bot (bot cars at 1 m/s).",
    )  # fmt: skip

    class Meta:
        model = Event
        fields = [
            "name", "track", "direction", "race_type", "obstacles", "opens_at", "closes_at",
            "ranking_method", "laps_required", "laps_to_drive", "off_track_penalty_s",
            "crash_penalty_s", "max_off_tracks_per_lap", "submissions_per_racer",
        ]  # fmt: skip
        widgets = {
            "opens_at": forms.DateTimeInput(attrs={"type": "datetime-local"}, format=LOCAL),
            "closes_at": forms.DateTimeInput(attrs={"type": "datetime-local"}, format=LOCAL),
        }
        help_texts = {"ranking_method": "The league's rule is the first; lower is better."}

    def __init__(self, *args, organiser, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.fields["ranking_method"].initial = RankingMethod.FIRST_CONSECUTIVE
        self.instance.organiser = organiser
        self.instance.public = False

    def clean(self) -> dict:
        data = super().clean()
        race_type = data.get("race_type")
        count = data.get("obstacles") or 3
        self.instance.boxes = (
            {"count": count, "randomize": False} if race_type == RaceType.OBJECT_AVOIDANCE else None
        )
        self.instance.bots = (
            {"count": count, "speed": 1.0, "lane_changes": False}
            if race_type == RaceType.HEAD_TO_BOT
            else None
        )
        return data

    def fields_for_service(self) -> dict:
        data = {name: self.cleaned_data[name] for name in self.Meta.fields if name != "obstacles"}
        return {**data, "boxes": self.instance.boxes, "bots": self.instance.bots}
