from django.contrib import messages
from django.contrib.admin.views.decorators import staff_member_required
from django.contrib.auth import login
from django.http import HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import redirect, render
from django.views.decorators.cache import never_cache
from django.views.decorators.http import require_safe

from console.forms import SignUpForm
from console.health import system_health
from racing.selectors import events_not_closed
from training.selectors import models_for_racer, vehicles_for_racer


def home(request: HttpRequest) -> HttpResponse:
    context = {"events": events_not_closed()[:3]}
    if request.user.is_authenticated:
        context["has_vehicle"] = vehicles_for_racer(racer=request.user).exists()
        context["models"] = models_for_racer(racer=request.user)[:5]
    return render(request, "console/home.html", context)


def signup(request: HttpRequest) -> HttpResponse:
    if request.user.is_authenticated:
        return redirect("home")
    form = SignUpForm(request.POST or None)
    if request.method == "POST" and form.is_valid():
        user = form.save()
        login(request, user, backend="django.contrib.auth.backends.ModelBackend")
        messages.success(request, f"Welcome to Pitlane, {user.username}!")
        return redirect("home")
    return render(
        request, "registration/signup.html", {"form": form}, status=400 if form.errors else 200
    )


@never_cache
@require_safe
def healthz(request: HttpRequest) -> JsonResponse:
    """Reachability of the database, Redis and the workers: 200 when all are up, else 503."""
    health = system_health()
    return JsonResponse(health, status=200 if health["status"] == "ok" else 503)


@staff_member_required
def system(request: HttpRequest) -> HttpResponse:
    return render(request, "console/system.html", {"health": system_health()})


def csrf_failure(request: HttpRequest, reason: str = "") -> HttpResponse:
    return render(request, "403_csrf.html", status=403)
