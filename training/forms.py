from django import forms

from training.models import Track, Vehicle
from training.rewards import MAX_SOURCE_SIZE


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

    def clean_name(self) -> str:
        name = self.cleaned_data["name"].strip()
        if Vehicle.objects.filter(owner=self.owner, name__iexact=name).exists():
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
