from django import forms
from django.conf import settings
from django.contrib.auth.base_user import BaseUserManager
from django.http import HttpRequest

from accounts.countries import COUNTRIES
from accounts.email_changes import ADDRESS_TAKEN, EMAIL_LINK_DAYS, address_taken
from accounts.models import RACER_NAME_RULE, AvatarColour, Profile, TokenScope
from accounts.tokens import EXPIRY_DAYS
from common import ratelimits
from common.forms import RacerWords

GUESS_LIMIT = "profile-password"  # wrong current passwords on the profile, per racer


class ProfileForm(RacerWords, forms.ModelForm):
    """The racer's profile page: what the leaderboards show, and the email address that reset
    links and notifications go to where the console sends email (``email_help``). Changing the
    address asks for the password, and an address belongs to one account
    (``accounts.email_changes``)."""

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
        error_messages={"invalid": "That is not an email address: it looks like name@example.org."},
    )
    password = forms.CharField(
        required=False,
        strip=False,
        label="Current password",
        widget=forms.PasswordInput(attrs={"autocomplete": "current-password"}),
        help_text="Needed only to change your email address.",
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

    def __init__(self, *args, request: HttpRequest | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.request = request  # whose wrong passwords count against the limit
        self.limited: ratelimits.Limited | None = None
        self.fields["email"].help_text = email_help()
        self.account = self.instance.user

    def clean_email(self) -> str:
        email = self.cleaned_data["email"].strip()
        if email and email != self.account.email:
            email = BaseUserManager.normalize_email(email)
        return email

    def clean(self) -> dict:
        """A new address needs the current password, checked within the limit on guesses
        (``GUESS_LIMIT``, counted only when it is wrong, like a sign-in's); whether
        another account has the address is said only once the password is right, so that the
        page tells nobody without it who has an account."""
        cleaned = super().clean()
        email, password = cleaned.get("email"), cleaned.get("password", "")
        if email is None or email == self.account.email:
            return cleaned
        if not password:
            self.add_error("password", "Enter your current password to change your email address.")
            return cleaned
        held = ratelimits.hold(self.request, GUESS_LIMIT) if self.request else None
        if held is not None and held.limited:
            self.limited = held.limited
            ratelimits.refuse(self, held.limited)
            return self.cleaned_data
        if not self.account.check_password(password):
            self.add_error(
                "password",
                "That is not your current password, so nothing was saved. Enter it again "
                "to change your email address.",
            )
            return cleaned
        if held is not None:
            held.give_back(GUESS_LIMIT)
        if address_taken(email=email, user=self.account):
            self.add_error("email", ADDRESS_TAKEN)
        return cleaned

    def clean_racer_name(self) -> str:
        name = self.cleaned_data["racer_name"].strip()
        taken = Profile.objects.filter(racer_name__iexact=name).exclude(pk=self.instance.pk)
        if taken.exists():
            raise forms.ValidationError(
                f"Another racer already races as {name} (racer names ignore capitals). Choose "
                "another."
            )
        return name


def email_help() -> str:
    """What goes to a racer's email address on this console: only what it sends, and nothing
    where its operator named no mail server (``PITLANE_EMAIL_URL``)."""
    sent = []
    if settings.PITLANE_PASSWORD_RESET_BY_EMAIL:
        sent.append("your password reset links")
    if settings.PITLANE_EMAIL_NOTIFICATIONS:
        sent.append("your notifications (training, evaluations and races ended)")
    if not sent:
        return (
            "This console sends no email (its operator has set up no mail server), so nothing "
            "goes here for now; never shown to other racers."
        )
    listed = " and ".join(sent)
    return (
        f"{listed[0].upper()}{listed[1:]} go here; never shown to other racers. A new address "
        f"takes over once you follow the link we email to it (within {EMAIL_LINK_DAYS} days)."
    )


class AccessTokenForm(RacerWords, forms.Form):
    """A new personal access token on the profile page: a name, what it may do, how long."""

    name = forms.CharField(
        max_length=60,
        label="Token name",
        help_text="What it is for, such as 'laptop notebook' or 'club scripts'.",
        error_messages={"required": "Give the token a name, to tell it from your others."},
    )
    scopes = forms.MultipleChoiceField(
        choices=TokenScope.choices,
        widget=forms.CheckboxSelectMultiple,
        label="It may",
        error_messages={
            "required": "Choose what the token may do: read, train, race or admin.",
            "invalid_choice": "Choose what the token may do from the list.",
        },
    )
    days = forms.TypedChoiceField(
        choices=[(days, f"{days} days") for days in EXPIRY_DAYS],
        coerce=int,
        initial=30,
        label="It expires after",
        error_messages={"invalid_choice": "Choose how long the token lasts from the list."},
    )

    def __init__(self, *args, staff: bool = False, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if not staff:  # admin is for league staff
            self.fields["scopes"].choices = [
                choice for choice in TokenScope.choices if choice[0] != TokenScope.ADMIN
            ]
