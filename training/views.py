from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import FileResponse, Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import redirect, render
from django.views.decorators.cache import cache_control
from django.views.decorators.http import require_POST, require_safe

from simulator import tracks as simulator_tracks
from training import rewards, selectors, services
from training.forms import RewardValidationForm, VehicleForm
from training.sandbox import SandboxFailure, SandboxUnavailable, verified


@login_required
def model_list(request: HttpRequest) -> HttpResponse:
    return render(
        request,
        "training/model_list.html",
        {
            "models": selectors.models_for_racer(racer=request.user),
            "tracks": selectors.tracks_available(),
        },
    )


@require_safe
@cache_control(public=True, max_age=86_400)
def track_preview(request: HttpRequest, name: str) -> FileResponse:
    """The top-down picture of a built-in track."""
    try:
        path = simulator_tracks.preview_path(name)
    except simulator_tracks.TrackError:
        raise Http404(f"No track named {name}") from None
    return FileResponse(open(path, "rb"), content_type="image/png")


@login_required
def garage(request: HttpRequest) -> HttpResponse:
    form = VehicleForm(request.POST or None, owner=request.user)
    if request.method == "POST" and form.is_valid():
        vehicle = services.vehicle_create(owner=request.user, **form.cleaned_data)
        messages.success(request, f"{vehicle.name} is in your garage.")
        return redirect("training:garage")
    return render(
        request,
        "training/garage.html",
        {"vehicles": selectors.vehicles_for_racer(racer=request.user), "form": form},
        status=400 if form.errors else 200,
    )


@login_required
def reward_editor(request: HttpRequest) -> HttpResponse:
    return render(
        request,
        "training/reward_editor.html",
        {
            "examples": rewards.EXAMPLES,
            "example_sources": {example.slug: example.source for example in rewards.EXAMPLES},
            "params": rewards.PARAMS,
            "tracks": selectors.tracks_available(),
            "source": rewards.EXAMPLES[0].source,
            "allowed_imports": rewards.ALLOWED_IMPORTS,
        },
    )


@login_required
@require_POST
def reward_validation(request: HttpRequest) -> JsonResponse:
    """Validate the posted reward function against the chosen track; JSON for the editor."""
    form = RewardValidationForm(request.POST)
    if not form.is_valid():
        return JsonResponse({"message": form.first_error()}, status=400)
    try:
        verified()
        result = rewards.reward_validate(
            source=form.cleaned_data["source"], track=form.cleaned_data["track"].name
        )
    except SandboxUnavailable as error:
        return JsonResponse({"message": str(error)}, status=503)
    except SandboxFailure as error:
        return JsonResponse({"message": f"Validation could not run: {error}"}, status=503)
    return JsonResponse(result.as_dict())
