from django import forms

from training.models import Vehicle


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
