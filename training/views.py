import json
import tempfile
from contextlib import nullcontext
from copy import copy

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.files.storage import default_storage
from django.http import (
    FileResponse,
    Http404,
    HttpRequest,
    HttpResponse,
    JsonResponse,
    StreamingHttpResponse,
)
from django.shortcuts import get_object_or_404, redirect, render
from django.urls import reverse
from django.utils.cache import patch_cache_control
from django.views.decorators.http import require_POST, require_safe

from console import ratelimits
from simulator import config as sim_config
from simulator import tracks as simulator_tracks
from training import (
    artifacts,
    configuration,
    exports,
    imports,
    jobs,
    logs_archive,
    rewards,
    selectors,
    services,
)
from training.evaluation import METRICS as EVALUATION_METRICS
from training.evaluation import TRACE as EVALUATION_TRACE
from training.evaluation import VIDEO as EVALUATION_VIDEO
from training.evaluation import files_prefix
from training.forms import (
    EvaluationForm,
    ModelCreateForm,
    ModelImportForm,
    RewardFunctionForm,
    RewardValidationForm,
    VehicleForm,
)
from training.models import EvaluationJob, JobLogLine, RewardFunction, RLModel, Vehicle
from training.sandbox import SandboxFailure, SandboxUnavailable


@login_required
def model_list(request: HttpRequest) -> HttpResponse:
    return render(
        request,
        "training/model_list.html",
        {
            "models": selectors.models_with_training(racer=request.user),
            "tracks": selectors.tracks_available(),
        },
    )


@require_safe
def track_preview(request: HttpRequest, name: str) -> HttpResponse:
    """The top-down picture of a track: a built-in one's file, or the one stored with an added
    track (cached for less time: staff may replace the track)."""
    preview = selectors.track_added_preview(name=name)
    if preview is not None:
        response = HttpResponse(preview, content_type="image/png")
        patch_cache_control(response, public=True, max_age=300)
        return response
    try:
        path = simulator_tracks.preview_path(name)
    except simulator_tracks.TrackError:
        raise Http404(f"No track named {name}") from None
    response = FileResponse(open(path, "rb"), content_type="image/png")  # noqa: SIM115 (it closes)
    patch_cache_control(response, public=True, max_age=86_400)
    return response


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
        {"vehicles": selectors.vehicles_in_garage(racer=request.user), "form": form},
        status=400 if form.errors else 200,
    )


def _get_vehicle_for_user(request: HttpRequest, pk: int) -> Vehicle:
    """The racer's own vehicle, or 404."""
    return get_object_or_404(Vehicle, pk=pk, owner=request.user)


@login_required
def vehicle_edit(request: HttpRequest, pk: int) -> HttpResponse:
    vehicle = _get_vehicle_for_user(request, pk)
    # The form writes what was typed into its instance: give it its own copy of the row.
    form = VehicleForm(request.POST or None, instance=copy(vehicle), owner=request.user)
    if request.method == "POST" and form.is_valid():
        try:
            services.vehicle_update(vehicle=vehicle, **form.cleaned_data)
        except services.VehicleSensorsLocked as locked:
            form.add_error(None, str(locked))
        else:
            messages.success(request, f"{vehicle.name} is saved.")
            return redirect("training:garage")
    return render(
        request,
        "training/vehicle_edit.html",
        {"vehicle": vehicle, "form": form},
        status=400 if form.errors else 200,
    )


@login_required
def vehicle_delete(request: HttpRequest, pk: int) -> HttpResponse:
    """Asks first (GET); removes the vehicle, not its models (POST)."""
    vehicle = _get_vehicle_for_user(request, pk)
    if request.method == "POST":
        services.vehicle_delete(vehicle=vehicle)
        messages.success(request, f"{vehicle.name} has left your garage.")
        return redirect("training:garage")
    models = selectors.models_for_racer(racer=request.user).filter(vehicle=vehicle)
    return render(request, "training/vehicle_delete.html", {"vehicle": vehicle, "models": models})


def _get_reward_function_for_user(request: HttpRequest, pk: int) -> RewardFunction:
    """The racer's own saved reward function, or 404."""
    return get_object_or_404(RewardFunction, pk=pk, owner=request.user)


@login_required
def reward_editor(request: HttpRequest, pk: int | None = None) -> HttpResponse:
    """Write, validate and save a reward function in the racer's library (``pk``: open a saved
    one to change it); "Save and create a model" goes on to the create form with it."""
    function = _get_reward_function_for_user(request, pk) if pk is not None else None
    form = RewardFunctionForm(
        request.POST or None,
        initial={"name": function.name if function else "", "track": "rookie-loop"},
    )
    validation = None
    if request.method == "POST" and form.is_valid():
        try:
            saved = services.reward_function_save(
                owner=request.user,
                reward_function=function,
                name=form.cleaned_data["name"],
                source=form.cleaned_data["source"],
                track=form.cleaned_data["track"].name,
            )
        except services.RewardFunctionInvalid as invalid:
            for field, message in invalid.errors.items():
                form.add_error(field, message)
            validation = invalid.validation
        except (SandboxUnavailable, SandboxFailure) as error:
            form.add_error("source", f"The reward function could not be checked: {error}")
        else:
            messages.success(request, f"Saved “{saved.name}”.")
            if request.POST.get("then") == "create":
                return redirect(f"{reverse('training:model-create')}?reward={saved.pk}")
            return redirect("training:reward-function", pk=saved.pk)
    if form.is_bound:
        source = form.data.get("source", "")
    else:
        source = function.source if function else rewards.EXAMPLES[0].source
    library = selectors.reward_functions_for_racer(racer=request.user)
    return render(
        request,
        "training/reward_editor.html",
        {
            "form": form,
            "function": function,
            "library": library,
            "library_sources": {saved.pk: saved.source for saved in library},
            "validation": validation.as_dict() if validation else None,
            "examples": rewards.EXAMPLES,
            "example_sources": {example.slug: example.source for example in rewards.EXAMPLES},
            "params": rewards.PARAMS,
            "tracks": selectors.tracks_available(),
            "try_on_track": form["track"].value(),
            "source": source,
            "allowed_imports": rewards.ALLOWED_IMPORTS,
        },
        status=400 if form.errors else 200,
    )


@login_required
def reward_function_delete(request: HttpRequest, pk: int) -> HttpResponse:
    """Asks first (GET); takes the function out of the racer's library (POST)."""
    function = _get_reward_function_for_user(request, pk)
    if request.method == "POST":
        services.reward_function_delete(reward_function=function)
        messages.success(request, f"Deleted “{function.name}”. Models created with it keep it.")
        return redirect("training:reward-editor")
    return render(request, "training/reward_function_delete.html", {"function": function})


@login_required
@require_POST
def reward_validation(request: HttpRequest) -> JsonResponse:
    """Validate the posted reward function against the chosen track; JSON for the editor."""
    if limited := ratelimits.over(request, "validate"):
        return JsonResponse({"message": str(limited)}, status=429)
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


def _number(text: str) -> int:
    if not text.isdigit():
        raise Http404("No such model")
    return int(text)


def _get_model_for_user(request: HttpRequest, pk: int) -> RLModel:
    """The racer's own model, or 404: no view can forget whose model it is."""
    return get_object_or_404(RLModel.objects.select_related("track"), pk=pk, owner=request.user)


@login_required
def model_create(request: HttpRequest) -> HttpResponse:
    """The create-model wizard; with ``?clone=<id>``, filled in from that model of the racer's,
    whose best weights the new model starts from."""
    source = None
    if "clone" in request.GET:
        source = _get_model_for_user(request, _number(request.GET["clone"]))
        if not source.trainable:
            messages.error(
                request,
                f"{source.name} cannot be cloned: it came from a car archive, "
                "with its policy alone (no reward function, no critics) to train on.",
            )
            return redirect("training:model-detail", pk=source.pk)
        initial = ModelCreateForm.initial_from(source)
    else:
        initial = {
            "reward_function": rewards.EXAMPLES[0].source,
            "actions": json.dumps(sim_config.DiscreteActions(
                tuple((a["steering_angle"], a["speed"]) for a in sim_config.DEFAULT_ACTION_SPACE)
            ).metadata()),
            "track": "rookie-loop",
        }  # fmt: skip
    chosen_reward = None
    if "reward" in request.GET:  # "Create a model" with a function of the racer's library
        chosen_reward = _get_reward_function_for_user(request, _number(request.GET["reward"]))
        initial["reward_function"] = chosen_reward.source
    reward_library = selectors.reward_functions_for_racer(racer=request.user)
    form = ModelCreateForm(request.POST or None, owner=request.user, initial=initial, source=source)
    if limited := ratelimits.over(request, "create"):
        ratelimits.refuse(form, limited)
    elif request.method == "POST" and form.is_valid():
        try:
            inherited = (
                {"cloned_from": source, "shell_colour": source.shell_colour} if source else {}
            )
            model = services.model_create(
                owner=request.user, settings={**inherited, **form.settings()}
            )
        except configuration.Invalid as invalid:
            form.add_setting_errors(invalid.errors)
        except (SandboxUnavailable, SandboxFailure) as error:
            form.add_error("reward_function", f"The reward function could not be checked: {error}")
        else:
            created = "cloned from " + source.name if source else "created"
            messages.success(request, f"{model.name} is {created}; its training is queued.")
            return redirect("training:model-detail", pk=model.pk)
    return render(
        request,
        "training/model_create.html",
        {
            "form": form,
            "source": source,
            "allowance": selectors.allowance_for(racer=request.user),
            "ppo_fields": form.hyperparameter_fields("clipped_ppo"),
            "sac_fields": form.hyperparameter_fields("sac"),
            "tracks": selectors.tracks_available(),
            "examples": rewards.EXAMPLES,
            "example_sources": {example.slug: example.source for example in rewards.EXAMPLES},
            "params": rewards.PARAMS,
            "reward_library": reward_library,
            "reward_library_sources": {f.pk: f.source for f in reward_library},
            "chosen_reward": chosen_reward,
        },
        status=429 if limited else 400 if form.errors else 200,
    )


@login_required
def model_detail(request: HttpRequest, pk: int) -> HttpResponse:
    model = _get_model_for_user(request, pk)
    job = model.latest_job
    iterations = list(job.iteration_rows.all()) if job else []
    log_source = request.GET.get("log", "")
    if log_source not in JobLogLine.Source.values:
        log_source = ""
    return render(
        request,
        "training/model_detail.html",
        {
            "model": model,
            "job": job,
            "queue_position": jobs.queue_position(job) if job else None,
            "iterations": iterations,
            "evaluations": selectors.evaluations_for_model(model=model)[:20],
            "races": selectors.races_for_model(model=model)[:20],
            "can_evaluate": model.status == RLModel.Status.READY,
            "can_delete": model.status in RLModel.DELETABLE,
            "checkpoints": selectors.model_checkpoint_choices(model=model),
            "workers_range": range(model.workers),
            "clock": selectors.training_clock(job=job) if job else None,
            "log_lines": selectors.job_log(job=job, source=log_source) if job else [],
            "log_source": log_source,
            "log_sources": JobLogLine.Source.choices,
            "files": selectors.model_files(model=model),
        },
    )


@login_required
def model_stop(request: HttpRequest, pk: int) -> HttpResponse:
    """Asks first (GET: what stopping does; the model page asks in a dialog), then stops the
    model's training (POST)."""
    model = _get_model_for_user(request, pk)
    job = model.latest_job
    if job is None or not job.is_active:
        messages.error(request, "This model is not training.")
        return redirect("training:model-detail", pk=model.pk)
    if request.method == "POST":
        job = services.training_stop(job=job)
        if job.status == job.Status.CANCELED:
            messages.success(request, "Canceled: the model had not started training.")
        else:
            messages.success(request, f"Stopping: {job.message[0].lower()}{job.message[1:]}.")
        return redirect("training:model-detail", pk=model.pk)
    return render(
        request, "training/model_stop.html",
        {"model": model, "job": job, "clock": selectors.training_clock(job=job)},
    )  # fmt: skip


@login_required
@require_safe
def model_log(request: HttpRequest, pk: int) -> StreamingHttpResponse:
    """The whole training log of the model, as a text file."""
    model = _get_model_for_user(request, pk)
    response = StreamingHttpResponse(
        selectors.model_log_lines(model=model), content_type="text/plain; charset=utf-8"
    )
    response["Content-Disposition"] = f'attachment; filename="{model.name}-training-log.txt"'
    return response


@login_required
@require_safe
def model_file(request: HttpRequest, pk: int, relative: str) -> HttpResponse:
    """One of the model's files (metrics, simulation traces), after the ownership check."""
    model = _get_model_for_user(request, pk)
    if relative not in {f.relative for f in selectors.model_files(model=model)}:
        raise Http404("No such file")
    return artifacts.download(artifacts.path(model, relative), relative.replace("/", "-"))


@login_required
@require_safe
def model_export(request: HttpRequest, pk: int, kind: str) -> HttpResponse:
    """The physical-car or ONNX archive (of the ``checkpoint`` asked for, best by default) or the
    virtual-model archive, built on first request and kept in the model's storage."""
    model = _get_model_for_user(request, pk)
    which = request.GET.get("checkpoint", "best")
    if which not in ("best", "last"):
        messages.error(request, "Choose the best or the last checkpoint.")
        return redirect("training:model-detail", pk=model.pk)
    try:
        if kind == "virtual":
            export = exports.virtual(model)
        else:
            export = {"physical": exports.physical, "onnx": exports.onnx}[kind](model, which)
    except exports.ExportRefused as refused:
        messages.error(request, str(refused))
        return redirect("training:model-detail", pk=model.pk)
    return artifacts.download(export.name, export.filename, content_type="application/gzip")


@login_required
@require_safe
def model_logs(request: HttpRequest, pk: int) -> HttpResponse:
    """The model's logs, laid out as a DeepRacer model folder (``training.logs_archive``), built
    for this request: its traces grow while it trains."""
    model = _get_model_for_user(request, pk)
    archive = tempfile.TemporaryFile()  # noqa: SIM115 (the response closes it once sent)
    try:
        logs_archive.write(model, archive)
    except logs_archive.LogsRefused as refused:
        archive.close()
        messages.error(request, str(refused))
        return redirect("training:model-detail", pk=model.pk)
    archive.seek(0)
    response = FileResponse(archive, as_attachment=True, filename=logs_archive.filename(model))
    response["Content-Type"] = "application/gzip"
    return response


@login_required
def model_import(request: HttpRequest) -> HttpResponse:
    """The import form. An attempt that has to be corrected keeps the racer's archive (unless
    the archive itself was refused), so the next one need not choose it again."""
    if request.method != "POST":
        imports.upload_discard(session=request.session)
        form = ModelImportForm(owner=request.user)
        return render(request, "training/model_import.html", {"form": form})
    kept = imports.upload_kept(session=request.session, token=request.POST.get("kept", ""))
    form = ModelImportForm(request.POST, request.FILES, owner=request.user, kept=kept)
    refused = False
    if limited := ratelimits.over(request, "import"):
        ratelimits.refuse(form, limited)
        form.keep(kept)  # the racer tries again later with the archive they chose
        return render(request, "training/model_import.html", {"form": form}, status=429)
    if form.is_valid():
        upload = form.cleaned_data["archive"]
        try:
            with nullcontext(upload) if upload else kept.open() as archive:
                imported = imports.import_model(
                    owner=request.user, archive=archive, name=form.cleaned_data["name"]
                )
        except imports.ImportRefused as refusal:
            form.add_error("archive", str(refusal))
            refused = True
        except configuration.Invalid as invalid:
            _import_errors(form, invalid.errors)
            refused = not set(invalid.errors) <= RACERS_TO_FIX  # else the archive is at fault
        except (SandboxUnavailable, SandboxFailure) as error:
            form.add_error(None, f"The reward function could not be checked: {error}")
        else:
            imports.upload_discard(session=request.session)
            model = imported.model
            ready = model.status == RLModel.Status.READY
            messages.success(request, f"Imported {model.name}" + (
                ": it is ready to evaluate, clone or download." if ready
                else "; its training is queued."))  # fmt: skip
            for note in imported.notes:
                messages.warning(request, note)
            return redirect("training:model-detail", pk=model.pk)
    upload = request.FILES.get("archive")
    if refused or ("archive" in form.errors and upload is not None):
        imports.upload_discard(session=request.session)  # the racer must choose another
        form.keep(None)
    elif upload is not None:
        form.keep(imports.upload_keep(session=request.session, upload=upload))
    return render(request, "training/model_import.html", {"form": form}, status=400)


RACERS_TO_FIX = {"name", "quota", "max_minutes"}  # an import's problems the racer can fix


def _import_errors(form: ModelImportForm, errors: dict[str, str]) -> None:
    """The settings an archive brought that cannot be used, each where the racer can act."""
    for setting, message in errors.items():
        if setting == "name":
            form.add_error("name", message)
        else:  # a setting the archive brought: say which
            label = setting.split(".")[-1].replace("_", " ").capitalize()
            form.add_error(None, f"{label}: {message}")


@login_required
@require_safe
def model_name_check(request: HttpRequest) -> JsonResponse:
    """Whether the racer may give a new model this name, for forms that check as they type."""
    name = request.GET.get("name", "").strip()
    problem = configuration.name_problem(name, owner=request.user) if name else None
    return JsonResponse({"name": name, "ok": problem is None, "message": problem or ""})


@login_required
def model_delete(request: HttpRequest, pk: int) -> HttpResponse:
    """Asks first (GET); deletes the model and all its files (POST)."""
    model = _get_model_for_user(request, pk)
    if request.method == "POST":
        try:
            services.model_delete(model=model)
        except services.ModelBusy as busy:
            messages.error(request, str(busy))
            return redirect("training:model-detail", pk=model.pk)
        messages.success(request, f"Deleted {model.name} and all its files.")
        return redirect("training:model-list")
    return render(request, "training/model_delete.html", {"model": model})


@login_required
def evaluation_create(request: HttpRequest, pk: int) -> HttpResponse:
    model = _get_model_for_user(request, pk)
    initial = {"track": model.track.name, "direction": model.direction,
               "race_type": model.race_type}  # fmt: skip
    form = EvaluationForm(
        request.POST or None, initial=initial,
        checkpoints=selectors.model_checkpoint_choices(model=model),
    )  # fmt: skip
    refusal = limited = None
    if model.status != RLModel.Status.READY:
        refusal = (
            f"{model.name} is {model.get_status_display().lower()}; "
            "it can be evaluated once it is ready."
        )
    elif limited := ratelimits.over(request, "evaluate"):
        refusal = str(limited)
    elif request.method == "POST" and form.is_valid():
        try:
            evaluation = services.evaluation_start(model=model, settings=form.settings())
        except configuration.Invalid as invalid:
            form.add_setting_errors(invalid.errors)
        except services.EvaluationRefused as refused:
            refusal = str(refused)
        else:  # no message: the page's status line says queued, then follows the evaluation
            return redirect("training:evaluation-detail", pk=model.pk, evaluation=evaluation.pk)
    return render(
        request,
        "training/evaluation_create.html",
        {"model": model, "form": form, "refusal": refusal,
         "tracks": selectors.tracks_available()},
        status=429 if limited else
        400 if form.errors or (refusal and request.method == "POST") else 200,
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
def evaluation_file(request: HttpRequest, pk: int, evaluation: int, name: str) -> HttpResponse:
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
    return artifacts.download(
        stored, filename, attachment=not video, content_type="video/webm" if video else None
    )
