from django.contrib.auth.forms import UserCreationForm


class SignUpForm(UserCreationForm):
    """A racer's account: a racer name (shown on leaderboards) and a password."""

    class Meta(UserCreationForm.Meta):
        fields = ["username"]
        labels = {"username": "Racer name"}
        help_texts = {
            "username": "Shown on leaderboards. Up to 150 letters, digits and @ . + - _ characters."
        }
