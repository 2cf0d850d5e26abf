from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import HttpRequest, HttpResponse
from django.shortcuts import redirect, render

from training import selectors, services
from training.forms import VehicleForm


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
