from django import forms

from accounts.countries import COUNTRIES
from accounts.models import RACER_NAME_RULE, AvatarColour, Profile
from common.forms import RacerWords


class ProfileForm(RacerWords, forms.ModelForm):
    """The racer's profile page: what the leaderboards show, and the email address that reset
    links and notifications go to."""

    country = forms.ChoiceField(
        choices=[("", "Not shown"), *sorted(COUNTRIES.items(), key=lambda item: item[1])],
        required=False,
        help_text="Its code appears beside your racer name on leaderboards.",
        error_messages={"invalid_choice": "Choose your country from the list, or Not shown."},
    )
    avatar_colour = forms.ChoiceField(
        choices=AvatarColour.choices,
        widget=forms.RadioSelect,
        label="Avatar colour",
        error_messages={"invalid_choice": "Choose one of the colours shown."},
        help_text="Your avatar is your racer name's first letter in a circle of this colour.",
    )
    email = forms.EmailField(
        required=False,
        label="Email address",
        help_text="Where this console sends email, your password reset links and your "
        "notifications (training, evaluations and races ended) go here; never shown to other "
        "racers.",
        error_messages={"invalid": "That is not an email address: it looks like name@example.org."},
    )

    class Meta:
        model = Profile
        fields = ["racer_name", "country", "avatar_colour"]
        labels = {"racer_name": "Racer name"}
        help_texts = {
            "racer_name": f"Shown on leaderboards instead of your login name: {RACER_NAME_RULE}."
        }
        error_messages = {
            "racer_name": {
                "required": "Choose a racer name for the leaderboards.",
                "min_length": f"A racer name is {RACER_NAME_RULE}; that one has %(show_value)d.",
                "max_length": f"A racer name is {RACER_NAME_RULE}; that one has %(show_value)d.",
            }
        }
        widgets = {
            "racer_name": forms.TextInput(attrs={"data-racer-name": "", "autocomplete": "nickname"})
        }

    def clean_racer_name(self) -> str:
        name = self.cleaned_data["racer_name"].strip()
        taken = Profile.objects.filter(racer_name__iexact=name).exclude(pk=self.instance.pk)
        if taken.exists():
            raise forms.ValidationError(
                f"Another racer already races as {name} (racer names ignore capitals). Choose "
                "another."
            )
        return name
