from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import HttpRequest, HttpResponse
from django.shortcuts import redirect, render

from accounts.forms import ProfileForm
from accounts.services import RacerNameTaken, profile_ensure, profile_update


@login_required
def profile(request: HttpRequest) -> HttpResponse:
    """The racer's profile: their racer name, country and avatar as leaderboards show them,
    their email address for password resets, and the way to change their password."""
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
        request, "accounts/profile.html", {"form": form}, status=400 if form.errors else 200
    )
