"""League staff find a racer by login or racer name, see their profile, and set a new password
for a racer who forgot theirs (the console's "Forgot your password?" page sends them here where
the site sends no email). Administrators see racers' API tokens and revoke one that leaked."""

from django import forms
from django.contrib import admin
from django.contrib.auth.admin import UserAdmin
from django.contrib.auth.forms import UserChangeForm
from django.contrib.auth.models import User
from django.utils import timezone

from accounts.email_changes import ADDRESS_TAKEN, address_taken
from accounts.models import AccessToken, Profile

STAFF_RESET_HINT = (
    "A racer who forgot their password: press <strong>Reset password</strong> under Password "
    "below, set a new one, and tell it to them privately; they can change it on their profile "
    "page once logged in."
)


class ProfileInline(admin.StackedInline):
    model = Profile
    can_delete = False
    verbose_name = "racer profile"
    fields = ["racer_name", "country", "avatar_colour"]


class RacerChangeForm(UserChangeForm):
    """Staff set an address at once (they are trusted, no link is sent), but not one that
    another account has, as on the racer's profile (``accounts.email_changes``)."""

    def clean_email(self) -> str:
        email = self.cleaned_data.get("email", "")
        if email != self.instance.email and address_taken(email=email, user=self.instance):
            raise forms.ValidationError(ADDRESS_TAKEN)
        return email


class RacerAdmin(UserAdmin):
    form = RacerChangeForm
    inlines = [ProfileInline]
    list_display = ["username", "racer_name", "email", "is_staff", "last_login"]
    list_select_related = ["profile"]
    search_fields = ["username", "profile__racer_name", "email"]
    fieldsets = (
        (None, {"fields": ("username", "password"), "description": STAFF_RESET_HINT}),
        *UserAdmin.fieldsets[1:],
    )

    def get_inline_instances(self, request, obj=None):
        # A new account gets its profile as it is saved; an inline there would add a second.
        return super().get_inline_instances(request, obj) if obj is not None else []

    @admin.display(description="Racer name", ordering="profile__racer_name")
    def racer_name(self, user: User) -> str:
        return getattr(getattr(user, "profile", None), "racer_name", "")


admin.site.unregister(User)
admin.site.register(User, RacerAdmin)


@admin.register(AccessToken)
class AccessTokenAdmin(admin.ModelAdmin):
    """Administrators (the rights to racers' tokens) see every racer's API tokens, never their
    secrets, which are not kept, and revoke one that leaked; a racer makes and revokes their
    own on their profile page."""

    list_display = ["name", "owner", "prefix", "scopes", "expires_at", "last_used_at", "revoked_at"]
    list_filter = ["revoked_at"]
    search_fields = ["name", "owner__username", "owner__profile__racer_name", "prefix"]
    fields = list_display
    readonly_fields = list_display
    actions = ["revoke"]

    def has_add_permission(self, request) -> bool:
        return False  # shown once to the racer who made it: staff cannot make one for them

    @admin.action(description="Revoke the selected tokens (they stop working at once)")
    def revoke(self, request, queryset) -> None:
        revoked = queryset.filter(revoked_at__isnull=True).update(revoked_at=timezone.now())
        self.message_user(request, f"Revoked {revoked} token{'s' if revoked != 1 else ''}.")
