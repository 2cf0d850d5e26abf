"""The training app's pages: the garage, reward functions, models (create, detail, clone,
delete), training and evaluations. A model's downloads and the import are archives' pages.

Long because these are the app's pages, thin over its services and selectors, in one module as
Django apps keep them; each view is short.
"""

import json
from copy import copy

from asgiref.sync import sync_to_async
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

from common import ratelimits
from common.refusals import Refused
from sandbox import SandboxFailure
from simulator import config as sim_config
from simulator import randomisation_ranges
from simulator import tracks as simulator_tracks
from training import (
    artifacts,
    checkers,
    configuration,
    rewards,
    selectors,
    services,
    track_lines,
)
from training.forms import (
    EvaluationForm,
    ModelCreateForm,
    RewardFunctionForm,
    RewardValidationForm,
    TrackLineForm,
    VehicleForm,
    training_settings_shown,
)
from training.models import Algorithm, EvaluationJob, JobLogLine, RewardFunction, RLModel, Vehicle


@login_required
def model_list(request: HttpRequest) -> HttpResponse:
    # A NUL is dropped: PostgreSQL refuses one in a query's text (a 500 on ?q=%00).
    search = request.GET.get("q", "").replace("\x00", "")[:100]
    sort = request.GET.get("sort", "")
    return render(
        request,
        "training/model_list.html",
        {
            "models": selectors.models_with_training(racer=request.user),
            "tracks": selectors.tracks_listed(search=search, sort=sort),
            "track_search": search,
            "track_sort": sort,
        },
    )


@login_required
@require_safe
def track_detail(request: HttpRequest, name: str) -> HttpResponse:
    """A track: its facts, and its racing line in a direction and margin (the query's), drawn by
    speed, with its lap times and the literal a reward function pastes."""
    track = selectors.track_named(name=name)
    form = TrackLineForm(request.GET, track=track)
    if form.is_valid():
        direction, margin = form.cleaned_data["direction"], form.cleaned_data["margin"]
    else:
        direction, margin = track.default_direction, 0
    try:
        shown = track_lines.track_line(track=track, direction=direction, margin_cm=margin)
    except simulator_tracks.TrackError:  # a track that has left the simulator's catalogue
        raise Http404(f"{track.display_name} can no longer be driven here.") from None
    context = {
        "track": track,
        "form": form,
        "shown": shown,
        "drawing": track_lines.line_drawing(shown),
        "literal": track_lines.reward_literal(shown) if shown.line is not None else "",
    }
    return render(
        request, "training/track_detail.html", context, status=400 if form.errors else 200
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
async def reward_editor(request: HttpRequest, pk: int | None = None) -> HttpResponse:
    """Write, validate and save a reward function in the racer's library (``pk``: open a saved
    one to change it); "Save and create a model" goes on to the create form with it. The code is
    validated by a checker (``training.checkers``) before the page saves it."""
    function, form, limited = await sync_to_async(_reward_editor_form)(request, pk)
    checked = None
    if limited:
        checked = limited
    elif request.method == "POST" and await sync_to_async(form.is_valid)():
        source = services.reward_source(form.cleaned_data["source"])
        if source.strip():  # else the service says what is missing
            checked = await checkers.reward_checked(
                source, form.cleaned_data["track"].name, racer=(await request.auser()).pk
            )
    return await sync_to_async(_reward_editor_page)(request, function, form, checked)


def _reward_editor_form(
    request: HttpRequest, pk: int | None
) -> tuple[RewardFunction | None, RewardFunctionForm, ratelimits.Limited | None]:
    """The racer's function (or None), the form, and whether a save is over the racer's rate of
    checks (saving runs the same check as Validate, and counts with it)."""
    function = _get_reward_function_for_user(request, pk) if pk is not None else None
    form = RewardFunctionForm(
        request.POST or None,
        initial={"name": function.name if function else "", "track": "rookie-loop"},
    )
    return function, form, ratelimits.over(request, "validate")


def _reward_editor_page(
    request: HttpRequest,
    function: RewardFunction | None,
    form: RewardFunctionForm,
    checked: rewards.Validation | ratelimits.Limited | Exception | None,
) -> HttpResponse:
    validation = None
    if isinstance(checked, ratelimits.Limited):
        ratelimits.refuse(form, checked)
    elif isinstance(checked, Exception):
        form.add_error("source", checkers.failure_words(checked))
    elif request.method == "POST" and form.is_valid():
        try:
            saved = services.reward_function_save(
                owner=request.user,
                reward_function=function,
                name=form.cleaned_data["name"],
                source=form.cleaned_data["source"],
                track=form.cleaned_data["track"].name,
                validation=checked,
            )
        except services.RewardFunctionInvalid as invalid:
            for field, message in invalid.errors.items():
                form.add_error(field, message)
            validation = invalid.validation
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
    response = render(
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
        status=429 if isinstance(checked, ratelimits.Limited) else 400 if form.errors else 200,
    )
    if isinstance(checked, checkers.FAILURES):
        return checkers.failure_response(response, checked)
    return response


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
async def reward_validation(request: HttpRequest) -> JsonResponse:
    """Validate the posted reward function against the chosen track, in a checker; JSON for the
    editor."""
    if limited := await sync_to_async(ratelimits.over)(request, "validate"):
        return JsonResponse({"message": str(limited)}, status=429)
    form = RewardValidationForm(request.POST)
    if not await sync_to_async(form.is_valid)():
        return JsonResponse({"message": form.first_error()}, status=400)
    checked = await checkers.reward_checked(
        form.cleaned_data["source"],
        form.cleaned_data["track"].name,
        racer=(await request.auser()).pk,
    )
    if isinstance(checked, SandboxFailure):
        message = f"Validation could not run: {checked}"
    elif isinstance(checked, Exception):
        message = str(checked)
    else:
        return JsonResponse(checked.as_dict())
    return checkers.failure_response(JsonResponse({"message": message}), checked)


def _pk(text: str) -> int:
    """A row's id from a query string; 404 for anything else."""
    if not text.isdigit():
        raise Http404("No such model")
    return int(text)


def _get_model_for_user(request: HttpRequest, pk: int) -> RLModel:
    """The racer's own model, or 404: no view can forget whose model it is."""
    return selectors.model_of_racer(racer=request.user, pk=pk)


@login_required
async def model_create(request: HttpRequest) -> HttpResponse:
    """The create-model wizard; with ``?clone=<id>``, filled in from that model of the racer's,
    whose best weights the new model starts from. The reward function is validated by a checker
    (``training.checkers``), then the model is saved."""
    page = await sync_to_async(_ModelCreatePage)(request)
    if page.reward_where is not None:
        track, direction = page.reward_where
        page.checked = await checkers.reward_checked(
            page.settings["reward_function"],
            track,
            racer=(await request.auser()).pk,
            direction=direction,
        )
    return await sync_to_async(page.respond)()


class _ModelCreatePage:
    """The create-model page's work before its reward function is checked (the form, the
    racer's limit) and after (saving the model, or the page again with what to correct)."""

    def __init__(self, request: HttpRequest) -> None:
        self.request = request
        self.response: HttpResponse | None = None
        self.settings: configuration.Draft | None = None
        self.reward_where: tuple[str, str] | None = None
        self.checked: rewards.Validation | Exception | None = None
        self.source = None
        if "clone" in request.GET:
            self.source = _get_model_for_user(request, _pk(request.GET["clone"]))
            if not self.source.trainable:
                messages.error(
                    request,
                    f"{self.source.name} cannot be cloned: it came from a car archive, "
                    "with its policy alone (no reward function, no critics) to train on.",
                )
                self.response = redirect("training:model-detail", pk=self.source.pk)
                return
            initial = ModelCreateForm.initial_from(configuration.ModelSettings.of(self.source))
        else:
            initial = {
                "reward_function": rewards.EXAMPLES[0].source,
                "actions": json.dumps(
                    sim_config.DiscreteActions(
                        tuple(
                            (a["steering_angle"], a["speed"])
                            for a in sim_config.DEFAULT_ACTION_SPACE
                        )
                    ).metadata()
                ),
                # "Train a model on it" from a track's page names the track.
                "track": request.GET.get("track")
                if selectors.tracks_available().filter(name=request.GET.get("track", "")).exists()
                else "rookie-loop",
            }
        self.chosen_reward = None
        if "reward" in request.GET:  # "Create a model" with a function of the racer's library
            self.chosen_reward = _get_reward_function_for_user(request, _pk(request.GET["reward"]))
            initial["reward_function"] = self.chosen_reward.source
        self.form = ModelCreateForm(
            request.POST or None, owner=request.user, initial=initial, source=self.source
        )
        self.limited = ratelimits.over(request, "create")
        if self.limited:
            ratelimits.refuse(self.form, self.limited)
        elif request.method == "POST" and self.form.is_valid():
            self.settings = self.form.settings()
            if self.source is not None:
                self.settings.update(cloned_from=self.source, shell_colour=self.source.shell_colour)
            if (self.settings.get("reward_function") or "").strip():
                self.reward_where = configuration.reward_sample_track(self.settings)

    def respond(self) -> HttpResponse:
        if self.response is not None:
            return self.response
        form, source = self.form, self.source
        if isinstance(self.checked, Exception):
            form.add_error("reward_function", checkers.failure_words(self.checked))
        elif self.settings is not None:
            try:
                model = services.model_create(
                    owner=self.request.user, settings=self.settings, validation=self.checked
                )
            except configuration.Invalid as invalid:
                form.add_setting_errors(invalid.errors)
            else:
                created = "cloned from " + source.name if source else "created"
                messages.success(
                    self.request, f"{model.name} is {created}; its training is queued."
                )
                return redirect("training:model-detail", pk=model.pk)
        reward_library = selectors.reward_functions_for_racer(racer=self.request.user)
        response = render(
            self.request,
            "training/model_create.html",
            {
                "form": form,
                "source": source,
                "allowance": selectors.allowance_for(racer=self.request.user),
                "ppo_fields": form.hyperparameter_fields(Algorithm.PPO),
                "sac_fields": form.hyperparameter_fields(Algorithm.SAC),
                "tracks": selectors.tracks_available(),
                "examples": rewards.EXAMPLES,
                "example_sources": {example.slug: example.source for example in rewards.EXAMPLES},
                "params": rewards.PARAMS,
                "reward_library": reward_library,
                "reward_library_sources": {f.pk: f.source for f in reward_library},
                "chosen_reward": self.chosen_reward,
            },
            status=429 if self.limited else 400 if form.errors else 200,
        )
        if isinstance(self.checked, Exception):
            return checkers.failure_response(response, self.checked)
        return response


@login_required
def model_detail(request: HttpRequest, pk: int) -> HttpResponse:
    model = _get_model_for_user(request, pk)
    job = model.latest_job
    iterations = list(job.iteration_rows.all()) if job else []
    log_source = _log_source(request)
    untrained = selectors.model_untrained(model=model)
    return render(
        request,
        "training/model_detail.html",
        {
            "model": model,
            "job": job,
            "queue_words": selectors.queue_words(job=job) if job else "",
            "iterations": iterations,
            "time_split": selectors.time_split(row=iterations[-1]) if iterations else [],
            "evaluations": selectors.evaluations_for_model(model=model)[:20],
            "races": selectors.races_for_model(model=model)[:20],
            "can_evaluate": model.status == RLModel.Status.READY,
            "can_delete": model.status in RLModel.DELETABLE,
            "untrained": untrained,
            "untrained_words": selectors.UNTRAINED,
            "model_status_text": selectors.model_status_display(model=model, untrained=untrained),
            "checkpoints": selectors.model_checkpoint_choices(model=model),
            "workers_range": range(model.workers),
            "clock": selectors.training_clock(job=job) if job else None,
            "log_lines": selectors.job_log(job=job, source=log_source) if job else [],
            "log_source": log_source,
            "log_sources": JobLogLine.Source.choices,
            "files": selectors.model_files(model=model),
            "randomised_scene": randomisation_ranges.describe()
            if model.domain_randomisation
            else [],
            "imported_only": selectors.job_imported_only(job=job),
            "training_settings": training_settings_shown(
                algorithm=model.algorithm,
                stored=model.hyperparameters,
                max_minutes=model.max_minutes,
            ),
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
            said = f"Stopping: {job.message[0].lower()}{job.message[1:]}."
            messages.success(request, said, extra_tags="while-active")  # not once it has ended
        return redirect("training:model-detail", pk=model.pk)
    return render(
        request,
        "training/model_stop.html",
        {"model": model, "job": job, "clock": selectors.training_clock(job=job)},
    )


def _log_source(request: HttpRequest) -> str:
    """Whose lines the Log panel shows (``?log=``): one of the sources, or "" for all."""
    source = request.GET.get("log", "")
    return source if source in JobLogLine.Source.values else ""


@login_required
@require_safe
def model_log_panel(request: HttpRequest, pk: int) -> HttpResponse:
    """The model page's Log panel alone (its newest lines, in time order), for log.js to read
    again when the job says something new, instead of the whole page."""
    model = _get_model_for_user(request, pk)
    job = model.latest_job
    source = _log_source(request)
    return render(
        request,
        "training/includes/log_panel.html",
        {
            "model": model,
            "log_lines": selectors.job_log(job=job, source=source) if job else [],
            "log_source": source,
        },
    )


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
    return artifacts.download(request, artifacts.path(model, relative), relative.replace("/", "-"))


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
    initial = {
        "track": model.track.name,
        "direction": model.direction,
        "race_type": model.race_type,
    }
    form = EvaluationForm(
        request.POST or None,
        initial=initial,
        checkpoints=selectors.model_checkpoint_choices(model=model),
    )
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
        except Refused as refused:
            refusal = str(refused)
        else:  # no message: the page's status line says queued, then follows the evaluation
            return redirect("training:evaluation-detail", pk=model.pk, evaluation=evaluation.pk)
    return render(
        request,
        "training/evaluation_create.html",
        {
            "model": model,
            "form": form,
            "refusal": refusal,
            "tracks": selectors.tracks_available(),
            "untrained": selectors.model_untrained(model=model),
            "untrained_words": selectors.UNTRAINED,
        },
        status=429
        if limited
        else 400
        if form.errors or (refusal and request.method == "POST")
        else 200,
    )


def _get_evaluation_for_user(request: HttpRequest, pk: int, evaluation: int) -> EvaluationJob:
    model = _get_model_for_user(request, pk)
    return get_object_or_404(
        EvaluationJob.objects.select_related("model", "track"), pk=evaluation, model=model
    )


@login_required
def evaluation_detail(request: HttpRequest, pk: int, evaluation: int) -> HttpResponse:
    job = _get_evaluation_for_user(request, pk, evaluation)
    prefix = artifacts.path(job.model, artifacts.evaluation_prefix(job))
    ended = (EvaluationJob.Status.COMPLETED, EvaluationJob.Status.CANCELED)
    files = [
        (name, label)
        for name, label in artifacts.EVALUATION_FILES.items()
        if job.status in ended and default_storage.exists(prefix + name)
    ]
    stoppable = job.status in (
        EvaluationJob.Status.QUEUED,
        EvaluationJob.Status.INITIALIZING,
        EvaluationJob.Status.IN_PROGRESS,
    )
    line = selectors.evaluation_line(evaluation=job)
    return render(
        request,
        "training/evaluation_detail.html",
        {
            "model": job.model,
            "evaluation": job,
            "trials": selectors.evaluation_trials(evaluation=job, line=line),
            "line": line,
            "files": files,
            "cars": selectors.race_cars(evaluation=job),
            "can_stop": stoppable and not hasattr(job, "submission") and not job.rival,
        },
    )


@login_required
@require_POST
def evaluation_stop(request: HttpRequest, pk: int, evaluation: int) -> HttpResponse:
    """The racer's "Stop evaluation": the trials it finished are kept."""
    job = _get_evaluation_for_user(request, pk, evaluation)
    was_active = job.is_active
    try:
        job = services.evaluation_stop(evaluation=job)
    except Refused as refused:
        messages.error(request, str(refused))
    else:
        if not was_active:
            messages.info(request, f"The evaluation had already ended: {job.get_status_display()}.")
        elif job.status == EvaluationJob.Status.CANCELED:
            messages.success(request, "Stopped: the evaluation had not begun.")
        elif job.status == EvaluationJob.Status.STOPPING:
            messages.success(request, "Stopping the evaluation: the trials it finished are kept.")
        else:
            messages.info(request, f"The evaluation has ended: {job.get_status_display()}.")
    return redirect("training:evaluation-detail", pk=job.model_id, evaluation=job.pk)


@login_required
@require_safe
def evaluation_file(request: HttpRequest, pk: int, evaluation: int, name: str) -> HttpResponse:
    """The evaluation's video (played in the page), trace or metrics, after the ownership
    check."""
    job = _get_evaluation_for_user(request, pk, evaluation)
    try:
        return artifacts.evaluation_download(request, job, name)
    except FileNotFoundError:
        raise Http404("No such file") from None
