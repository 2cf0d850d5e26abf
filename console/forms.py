from django import forms
from django.contrib.auth.forms import (
    AuthenticationForm,
    PasswordChangeForm,
    PasswordResetForm,
    SetPasswordForm,
    UserCreationForm,
)

from common.forms import RacerWords


class SignUpForm(RacerWords, UserCreationForm):
    """A racer's account: a racer name (shown on leaderboards) and a password."""

    class Meta(UserCreationForm.Meta):
        fields = ["username"]
        labels = {"username": "Racer name"}
        help_texts = {
            "username": "You log in with it, and leaderboards show it until you choose another "
            "racer name on your profile. Up to 150 letters, digits and @ . + - _ characters."
        }


class PasswordResetRequestForm(RacerWords, PasswordResetForm):
    """The email address a forgotten password's reset link goes to."""

    email = forms.EmailField(
        label="Email address",
        max_length=254,
        widget=forms.EmailInput(attrs={"autocomplete": "email", "autofocus": True}),
        help_text="The one on your racer profile.",
        error_messages={
            "required": "Enter the email address on your racer profile.",
            "invalid": "That is not an email address: it looks like name@example.org.",
        },
    )


class SignInForm(RacerWords, AuthenticationForm):
    """Django's sign-in, in the site's words."""


class PasswordChangeInOurWords(RacerWords, PasswordChangeForm):
    """Django's password change, in the site's words."""


class NewPasswordForm(RacerWords, SetPasswordForm):
    """The new password a reset link sets, in the site's words."""
