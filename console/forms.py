from django import forms
from django.contrib.auth.forms import (
    AuthenticationForm,
    PasswordChangeForm,
    PasswordResetForm,
    SetPasswordForm,
    UserCreationForm,
)
from django.urls import reverse
from django.utils.html import format_html

from common.forms import RacerWords

LOGIN_NAME_CHARACTERS = "up to 150 letters, digits and @ . + - _ characters"


class SignUpForm(RacerWords, UserCreationForm):
    """A racer's account: a login name and a password. The racer name that leaderboards show
    is the profile's own, made from the login name and changeable there."""

    class Meta(UserCreationForm.Meta):
        fields = ["username"]
        labels = {"username": "Login name"}
        help_texts = {
            "username": "You log in with it; other racers never see it. Leaderboards show your "
            "racer name, which starts as this name (made to fit a racer name's rules and "
            "numbered where another racer has it) and can be changed on your profile. "
            f"{LOGIN_NAME_CHARACTERS[:1].upper()}{LOGIN_NAME_CHARACTERS[1:]}."
        }
        error_messages = {
            "username": {
                "unique": "Another racer already logs in with that login name. Choose another.",
                "invalid": f"A login name is {LOGIN_NAME_CHARACTERS}, no spaces.",
            }
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
    """Django's sign-in, in the site's words: the login name (not the racer name, which its
    racer may change on their profile) and the password."""

    error_messages = {
        **AuthenticationForm.error_messages,
        "invalid_login": "That login name and password do not match. Check both (passwords "
        "are case-sensitive) and try again.",
    }

    def __init__(self, request=None, *args, **kwargs) -> None:
        super().__init__(request, *args, **kwargs)
        self.fields["username"].label = "Login name"
        self.fields["password"].help_text = format_html(
            '<a href="{}">Forgot your password?</a>', reverse("password_reset")
        )


class PasswordChangeInOurWords(RacerWords, PasswordChangeForm):
    """Django's password change, in the site's words."""


class NewPasswordForm(RacerWords, SetPasswordForm):
    """The new password a reset link sets, in the site's words."""
