from django.conf import settings
from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import HttpRequest, HttpResponse
from django.shortcuts import redirect, render
from django.utils import timezone
from django.views.decorators.cache import never_cache
from django.views.decorators.http import require_POST

from accounts.email_changes import (
    ADDRESS_TAKEN,
    EMAIL_LINK_DAYS,
    AddressTaken,
    EmailChange,
    LinkRefused,
    email_change_confirm,
    pending_email_for_link,
)
from accounts.forms import AccessTokenForm, ProfileForm
from accounts.models import Profile
from accounts.services import RacerNameTaken, profile_ensure, profile_update
from accounts.tokens import TokenRefused, token_create, token_revoke, tokens_live

# What profile_update saves; the password is only the form's to check.
PROFILE_CHOICES = ("racer_name", "country", "avatar_colour", "email")


@login_required
def profile(request: HttpRequest) -> HttpResponse:
    """The racer's profile: their racer name, country and avatar as leaderboards show them,
    their email address, and how to change or reset their password."""
    current = profile_ensure(user=request.user)
    form = ProfileForm(
        request.POST or None,
        instance=current,
        initial={"email": request.user.email},
        request=request,
    )
    if request.method == "POST" and form.is_valid():
        chosen = {name: form.cleaned_data[name] for name in PROFILE_CHOICES}
        try:
            change = profile_update(profile=current, **chosen)
        except RacerNameTaken:
            form.add_error("racer_name", "Another racer took that racer name just now.")
        except AddressTaken:
            form.add_error("email", ADDRESS_TAKEN)
        else:
            messages.success(request, _saved_words(change, current))
            return redirect("accounts:profile")
    return _profile_page(
        request,
        form=form,
        status=form.limited.status if form.limited else 400 if form.errors else 200,
    )


def _profile_page(
    request: HttpRequest,
    *,
    form: ProfileForm | None = None,
    token_form: AccessTokenForm | None = None,
    secret: str = "",
    status: int = 200,
) -> HttpResponse:
    if form is None:
        current = profile_ensure(user=request.user)
        initial = {"email": request.user.email}
        form = ProfileForm(instance=current, initial=initial, request=request)
    return render(
        request,
        "accounts/profile.html",
        {
            "form": form,
            "token_form": token_form or AccessTokenForm(staff=request.user.is_staff),
            "tokens": tokens_live(owner=request.user),
            "secret": secret,
            "now": timezone.now(),
            "reset_by_email": settings.PITLANE_PASSWORD_RESET_BY_EMAIL,
            "link_days": EMAIL_LINK_DAYS,
        },
        status=status,
    )


@never_cache
@login_required
@require_POST
def token_new(request: HttpRequest) -> HttpResponse:
    """A new personal access token: the profile page again, its secret shown this once."""
    form = AccessTokenForm(request.POST, staff=request.user.is_staff)
    if form.is_valid():
        try:
            token, secret = token_create(owner=request.user, **form.cleaned_data)
        except TokenRefused as refused:
            form.add_error(None, str(refused))
        else:
            messages.success(request, f"Made the token {token.name}.")
            return _profile_page(request, secret=secret, status=201)
    return _profile_page(request, token_form=form, status=400)


@login_required
@require_POST
def token_revoked(request: HttpRequest, token_id: int) -> HttpResponse:
    token = token_revoke(owner=request.user, token_id=token_id)
    if token is None:
        messages.warning(request, "That token was already revoked, or is not yours.")
    else:
        messages.success(request, f"Revoked {token.name}: it no longer works.")
    return redirect("accounts:profile")  # its message at the top, where it is seen


def _saved_words(change: EmailChange, profile: Profile) -> str:
    if change is not EmailChange.PENDING:
        return "Your profile is saved."
    until = (
        f"until then, email still goes to {profile.user.email}"
        if profile.user.email
        else "until then, nothing is emailed to you"
    )
    return (
        f"Your profile is saved. To make {profile.pending_email} your email address, follow the "
        f"link we sent to it within {EMAIL_LINK_DAYS} days; {until}."
    )


@never_cache
@login_required
def email_confirm(request: HttpRequest, token: str) -> HttpResponse:
    """The link sent to a new email address: it shows the address, and its button makes it
    the logged-in racer's own (once, within its days, for the account that asked)."""
    try:
        if request.method == "POST":
            address = email_change_confirm(user=request.user, token=token)
            messages.success(request, f"{address} is now your email address.")
            return redirect("accounts:profile")
        address = pending_email_for_link(user=request.user, token=token)
    except LinkRefused as refused:
        return render(request, "accounts/email_confirm.html", {"refusal": str(refused)}, status=400)
    return render(request, "accounts/email_confirm.html", {"address": address})
