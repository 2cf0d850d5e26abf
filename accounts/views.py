from django.conf import settings
from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import HttpRequest, HttpResponse
from django.shortcuts import redirect, render

from accounts.forms import ProfileForm
from accounts.services import RacerNameTaken, profile_ensure, profile_update


@login_required
def profile(request: HttpRequest) -> HttpResponse:
    """The racer's profile: their racer name, country and avatar as leaderboards show them,
    their email address, and how to change or reset their password."""
    current = profile_ensure(user=request.user)
    form = ProfileForm(
        request.POST or None, instance=current, initial={"email": request.user.email}
    )
    if request.method == "POST" and form.is_valid():
        try:
            profile_update(profile=current, **form.cleaned_data)
        except RacerNameTaken:
            form.add_error("racer_name", "Another racer took that racer name just now.")
        else:
            messages.success(request, "Your profile is saved.")
            return redirect("accounts:profile")
    return render(
        request,
        "accounts/profile.html",
        {"form": form, "reset_by_email": settings.PITLANE_PASSWORD_RESET_BY_EMAIL},
        status=400 if form.errors else 200,
    )
