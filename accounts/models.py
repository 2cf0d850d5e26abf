"""A racer's profile: the name, country and avatar the leaderboards show for them."""

from __future__ import annotations

from django.conf import settings
from django.core.exceptions import ValidationError
from django.core.validators import MaxLengthValidator, MinLengthValidator, RegexValidator
from django.db import models
from django.db.models.functions import Lower

from accounts.countries import COUNTRIES, country_name

# DeepRacer's racer alias: 2 to 64 letters, digits, underscores and hyphens (DeepRacer on AWS,
# source/apps/website/src/constants/validation.ts: ALIAS_MIN_LENGTH, ALIAS_MAX_LENGTH, ALIAS_REGEX).
RACER_NAME_MIN, RACER_NAME_MAX = 2, 64
RACER_NAME_CHARACTERS = r"[A-Za-z0-9_-]"
RACER_NAME_RULE = (
    f"{RACER_NAME_MIN} to {RACER_NAME_MAX} letters, digits, hyphens (-) and underscores (_), "
    "no spaces"
)


def validate_country(code: str) -> None:
    if code and code not in COUNTRIES:
        raise ValidationError(f"{code!r} is not a country code we know (ISO 3166, such as NZ).")


class AvatarColour(models.TextChoices):
    """The avatar's circle, behind the racer name's initial in white: each dark enough to read."""

    TEAL = "teal", "Teal"
    BLUE = "blue", "Blue"
    PURPLE = "purple", "Purple"
    MAGENTA = "magenta", "Magenta"
    RED = "red", "Red"
    ORANGE = "orange", "Orange"
    GREEN = "green", "Green"
    SLATE = "slate", "Slate"


class Profile(models.Model):
    """What other racers see of a racer: their racer name (DeepRacer's alias) on every
    leaderboard, their country's code and an avatar. Every account has one from the start."""

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="profile"
    )
    racer_name = models.CharField(
        max_length=RACER_NAME_MAX,
        validators=[
            MinLengthValidator(RACER_NAME_MIN, f"A racer name is {RACER_NAME_RULE}."),
            MaxLengthValidator(RACER_NAME_MAX, f"A racer name is {RACER_NAME_RULE}."),
            RegexValidator(rf"\A{RACER_NAME_CHARACTERS}+\Z", f"A racer name is {RACER_NAME_RULE}."),
        ],
        help_text=f"Shown on leaderboards: {RACER_NAME_RULE}. Yours alone.",
    )
    country = models.CharField(
        max_length=2, blank=True, validators=[validate_country], help_text="ISO 3166 code."
    )
    avatar_colour = models.CharField(
        max_length=16, choices=AvatarColour.choices, default=AvatarColour.TEAL
    )
    # A new email address waits here until its racer follows the link sent to it
    # (accounts.email_changes): mail goes only to the account's own, verified address.
    pending_email = models.EmailField(blank=True, help_text="Not yet confirmed: nothing goes here.")
    pending_email_token = models.CharField(
        max_length=64, blank=True, help_text="SHA-256 of the confirmation link's token."
    )
    pending_email_sent_at = models.DateTimeField(null=True, blank=True)

    class Meta:
        constraints = [
            models.UniqueConstraint(
                Lower("racer_name"),
                name="accounts_profile_racer_name_unique",
                violation_error_message="Another racer already uses that racer name.",
            )
        ]

    def __str__(self) -> str:
        return self.racer_name

    @property
    def initial(self) -> str:
        return self.racer_name[:1].upper()

    @property
    def country_name(self) -> str:
        return country_name(self.country)


class TokenScope(models.TextChoices):
    """What a personal access token may do in the API (/api/v1/), a racer's pages' rules kept."""

    READ = "read", "Read: your models, their training and evaluations, and the league"
    TRAIN = "train", "Train: create, clone, stop, delete, import and evaluate your models"
    RACE = "race", "Race: submit your models to events and join live races"
    ADMIN = "admin", "Admin: the league staff's actions (staff only)"


class AccessToken(models.Model):
    """A racer's personal access token for the API: made on the profile page with a name, its
    scopes and an expiry, shown once, kept only as the SHA-256 of its secret (a leaked
    database gives no token), listed with its last use, and revocable."""

    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="access_tokens"
    )
    name = models.CharField(max_length=60)
    scopes = models.CharField(max_length=40, help_text="TokenScope values, space-separated.")
    prefix = models.CharField(max_length=12, help_text="The secret's start, to tell tokens apart.")
    digest = models.CharField(max_length=64, unique=True, help_text="SHA-256 of the secret.")
    created_at = models.DateTimeField(auto_now_add=True)
    expires_at = models.DateTimeField()
    last_used_at = models.DateTimeField(null=True, blank=True)
    revoked_at = models.DateTimeField(null=True, blank=True)

    class Meta:
        ordering = ["-created_at", "-pk"]
        constraints = [
            models.UniqueConstraint(
                "owner",
                "name",
                condition=models.Q(revoked_at__isnull=True),
                name="accounts_accesstoken_live_name_unique",
                violation_error_message="You already have a token of that name.",
            )
        ]

    def __str__(self) -> str:
        return f"{self.name} ({self.prefix}…)"

    @property
    def scope_set(self) -> frozenset[str]:
        return frozenset(self.scopes.split())
