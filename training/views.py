import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.files.storage import default_storage
from django.http import FileResponse, Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.views.decorators.cache import cache_control
from django.views.decorators.http import require_POST, require_safe

from simulator import config as sim_config
from simulator import tracks as simulator_tracks
from training import artifacts, configuration, jobs, rewards, selectors, services
from training.evaluation import METRICS as EVALUATION_METRICS
from training.evaluation import TRACE as EVALUATION_TRACE
from training.evaluation import VIDEO as EVALUATION_VIDEO
from training.evaluation import files_prefix
from training.forms import EvaluationForm, ModelCreateForm, RewardValidationForm, VehicleForm
from training.models import EvaluationJob, RLModel
from training.sandbox import SandboxFailure, SandboxUnavailable


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
        result = rewards.reward_validate(
            source=form.cleaned_data["source"], track=form.cleaned_data["track"].name
        )
    except SandboxUnavailable as error:
        return JsonResponse({"message": str(error)}, status=503)
    except SandboxFailure as error:
        return JsonResponse({"message": f"Validation could not run: {error}"}, status=503)
    return JsonResponse(result.as_dict())


def _get_model_for_user(request: HttpRequest, pk: int) -> RLModel:
    """The racer's own model, or 404: no view can forget whose model it is."""
    return get_object_or_404(RLModel.objects.select_related("track"), pk=pk, owner=request.user)


@login_required
def model_create(request: HttpRequest) -> HttpResponse:
    initial = {
        "reward_function": rewards.EXAMPLES[0].source,
        "actions": json.dumps(sim_config.DiscreteActions(
            tuple((a["steering_angle"], a["speed"]) for a in sim_config.DEFAULT_ACTION_SPACE)
        ).metadata()),
        "track": "rookie-loop",
    }  # fmt: skip
    form = ModelCreateForm(request.POST or None, owner=request.user, initial=initial)
    if request.method == "POST" and form.is_valid():
        try:
            model = services.model_create(owner=request.user, settings=form.settings())
        except configuration.Invalid as invalid:
            form.add_setting_errors(invalid.errors)
        except (SandboxUnavailable, SandboxFailure) as error:
            form.add_error("reward_function", f"The reward function could not be checked: {error}")
        else:
            messages.success(request, f"{model.name} is created; its training is queued.")
            return redirect("training:model-detail", pk=model.pk)
    return render(
        request,
        "training/model_create.html",
        {
            "form": form,
            "ppo_fields": form.hyperparameter_fields("clipped_ppo"),
            "sac_fields": form.hyperparameter_fields("sac"),
            "tracks": selectors.tracks_available(),
            "examples": rewards.EXAMPLES,
            "example_sources": {example.slug: example.source for example in rewards.EXAMPLES},
            "params": rewards.PARAMS,
        },
        status=400 if form.errors else 200,
    )


@login_required
def model_detail(request: HttpRequest, pk: int) -> HttpResponse:
    model = _get_model_for_user(request, pk)
    job = model.latest_job
    iterations = list(job.iteration_rows.all()) if job else []
    return render(
        request,
        "training/model_detail.html",
        {
            "model": model,
            "job": job,
            "queue_position": jobs.queue_position(job) if job else None,
            "iterations": iterations,
            "evaluations": selectors.evaluations_for_model(model=model)[:20],
            "can_evaluate": model.status == RLModel.Status.READY,
            "workers_range": range(model.workers),
            "log_lines": list(job.log_lines.all().order_by("-at", "-pk")[:200]) if job else [],
            "files": selectors.model_files(model=model),
        },
    )


@login_required
@require_POST
def model_stop(request: HttpRequest, pk: int) -> HttpResponse:
    model = _get_model_for_user(request, pk)
    job = model.latest_job
    if job is None or not job.is_active:
        messages.error(request, "This model is not training.")
    else:
        services.training_stop(job=job)
        messages.success(request, "Stopping: the model is saved from its last checkpoint.")
    return redirect("training:model-detail", pk=model.pk)


@login_required
@require_safe
def model_file(request: HttpRequest, pk: int, relative: str) -> FileResponse:
    """One of the model's files (metrics, simulation traces), after the ownership check."""
    model = _get_model_for_user(request, pk)
    if relative not in {f.relative for f in selectors.model_files(model=model)}:
        raise Http404("No such file")
    name = artifacts.path(model, relative)
    return FileResponse(default_storage.open(name, "rb"), as_attachment=True,
                        filename=relative.replace("/", "-"))  # fmt: skip


@login_required
def evaluation_create(request: HttpRequest, pk: int) -> HttpResponse:
    model = _get_model_for_user(request, pk)
    initial = {"track": model.track.name, "direction": model.direction,
               "race_type": model.race_type}  # fmt: skip
    form = EvaluationForm(request.POST or None, initial=initial)
    refusal = None
    if model.status != RLModel.Status.READY:
        refusal = (
            f"{model.name} is {model.get_status_display().lower()}; "
            "it can be evaluated once it is ready."
        )
    elif request.method == "POST" and form.is_valid():
        try:
            evaluation = services.evaluation_start(model=model, settings=form.settings())
        except configuration.Invalid as invalid:
            form.add_setting_errors(invalid.errors)
        except services.EvaluationRefused as refused:
            refusal = str(refused)
        else:
            messages.success(request, "The evaluation is queued.")
            return redirect("training:evaluation-detail", pk=model.pk, evaluation=evaluation.pk)
    return render(
        request,
        "training/evaluation_create.html",
        {"model": model, "form": form, "refusal": refusal,
         "tracks": selectors.tracks_available()},
        status=400 if form.errors or (refusal and request.method == "POST") else 200,
    )  # fmt: skip


def _get_evaluation_for_user(request: HttpRequest, pk: int, evaluation: int) -> EvaluationJob:
    model = _get_model_for_user(request, pk)
    return get_object_or_404(
        EvaluationJob.objects.select_related("model", "track"), pk=evaluation, model=model
    )


EVALUATION_FILES = {
    EVALUATION_VIDEO: "Video (WebM)",
    EVALUATION_TRACE: "Simulation trace (CSV)",
    EVALUATION_METRICS: "Evaluation metrics (JSON)",
}


@login_required
def evaluation_detail(request: HttpRequest, pk: int, evaluation: int) -> HttpResponse:
    job = _get_evaluation_for_user(request, pk, evaluation)
    prefix = artifacts.path(job.model, files_prefix(job))
    files = [
        (name, label) for name, label in EVALUATION_FILES.items()
        if job.status == EvaluationJob.Status.COMPLETED and default_storage.exists(prefix + name)
    ]  # fmt: skip
    return render(
        request,
        "training/evaluation_detail.html",
        {"model": job.model, "evaluation": job, "trials": list(job.trial_rows.all()),
         "files": files},
    )  # fmt: skip


@login_required
@require_safe
def evaluation_file(request: HttpRequest, pk: int, evaluation: int, name: str) -> FileResponse:
    """The evaluation's video (played in the page), trace or metrics, after the ownership
    check."""
    job = _get_evaluation_for_user(request, pk, evaluation)
    if name not in EVALUATION_FILES:
        raise Http404("No such file")
    stored = artifacts.path(job.model, files_prefix(job) + name)
    if not default_storage.exists(stored):
        raise Http404("No such file")
    video = name == EVALUATION_VIDEO
    filename = f"{job.model.name}-evaluation-{job.pk}-{name.replace('/', '-')}"
    response = FileResponse(default_storage.open(stored, "rb"), as_attachment=not video,
                            filename=filename)  # fmt: skip
    if video:
        response["Content-Type"] = "video/webm"
    return response
