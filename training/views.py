"""The training app's pages: the garage, reward functions, models (create, detail, clone,
delete, downloads, import), training and evaluations.

Long because these are the app's pages, thin over its services and selectors, in one module as
Django apps keep them; each view is short.
"""

import json
import tempfile
from contextlib import nullcontext
from copy import copy
from functools import partial

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

from archives import exports, imports, kept_uploads, logs_archive
from archives.models import KEPT_FOR, KeptUpload
from common import ratelimits
from common.downloads import file_response
from common.refusals import Refused
from sandbox import SandboxFailure, SandboxUnavailable
from simulator import config as sim_config
from simulator import randomisation_ranges
from simulator import tracks as simulator_tracks
from training import artifacts, checkers, configuration, rewards, selectors, services
from training.forms import (
    EvaluationForm,
    ModelCreateForm,
    ModelImportConfirmForm,
    ModelImportForm,
    RewardFunctionForm,
    RewardValidationForm,
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
            checked = await _checked_reward(request, source, form.cleaned_data["track"].name)
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
        form.add_error("source", _check_failed(checked))
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
    if isinstance(checked, CHECK_FAILURES):
        return _check_refused(response, checked)
    return response


async def _checked_reward(
    request: HttpRequest, source: str, track: str, direction: str = "counterclockwise"
) -> rewards.Validation | Exception:
    """``source`` validated on ``track`` by a checker, in the racer's turn; or why it could
    not be: ``checkers.Busy``, ``SandboxUnavailable`` or ``SandboxFailure``, for the page to
    show."""
    where = await sync_to_async(simulator_tracks.inline)(track)  # an added track: its route
    try:
        return await checkers.run(
            partial(rewards.reward_validate, source=source, track=where, direction=direction),
            racer=(await request.auser()).pk,
        )
    except CHECK_FAILURES as error:
        return error


CHECK_FAILURES = (checkers.Busy, SandboxUnavailable, SandboxFailure)


def _check_failed(error: Exception) -> str:
    """What a racer reads when a check could not run (one of ``CHECK_FAILURES``)."""
    if isinstance(error, checkers.Busy):
        return str(error)
    return f"The reward function could not be checked: {error}"


def _check_refused(response: HttpResponse, error: Exception) -> HttpResponse:
    """``response`` for a check that could not run: 503, for the racer's input is not at fault,
    and when every checker was busy, when to try again."""
    response.status_code = 503
    if isinstance(error, checkers.Busy):
        response["Retry-After"] = str(checkers.RETRY_AFTER)
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
    checked = await _checked_reward(
        request, form.cleaned_data["source"], form.cleaned_data["track"].name
    )
    if isinstance(checked, SandboxFailure):
        message = f"Validation could not run: {checked}"
    elif isinstance(checked, Exception):
        message = str(checked)
    else:
        return JsonResponse(checked.as_dict())
    return _check_refused(JsonResponse({"message": message}), checked)


def _pk(text: str) -> int:
    """A row's id from a query string; 404 for anything else."""
    if not text.isdigit():
        raise Http404("No such model")
    return int(text)


def _get_model_for_user(request: HttpRequest, pk: int) -> RLModel:
    """The racer's own model, or 404: no view can forget whose model it is."""
    return get_object_or_404(RLModel.objects.select_related("track"), pk=pk, owner=request.user)


@login_required
async def model_create(request: HttpRequest) -> HttpResponse:
    """The create-model wizard; with ``?clone=<id>``, filled in from that model of the racer's,
    whose best weights the new model starts from. The reward function is validated by a checker
    (``training.checkers``), then the model is saved."""
    page = await sync_to_async(_ModelCreatePage)(request)
    if page.reward_where is not None:
        page.checked = await _checked_reward(
            request, page.settings["reward_function"], *page.reward_where
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
                "track": "rookie-loop",
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
            form.add_error("reward_function", _check_failed(self.checked))
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
            return _check_refused(response, self.checked)
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
    return artifacts.download(
        request, export.name, export.filename, content_type="application/gzip"
    )


@login_required
@require_safe
def model_logs(request: HttpRequest, pk: int) -> HttpResponse:
    """The model's logs, laid out as a DeepRacer model folder (``archives.logs_archive``), built
    for this request: its traces grow while it trains."""
    model = _get_model_for_user(request, pk)
    archive = tempfile.TemporaryFile()  # noqa: SIM115 (the response closes it once sent)
    try:
        logs_archive.write(model, archive)
    except logs_archive.LogsRefused as refused:
        archive.close()
        messages.error(request, str(refused))
        return redirect("training:model-detail", pk=model.pk)
    return file_response(
        request,
        archive,
        filename=logs_archive.filename(model),
        attachment=True,
        content_type="application/gzip",
        ranges=False,  # built for this request: another's bytes differ
    )


@login_required
async def model_import(request: HttpRequest) -> HttpResponse:
    """The import form. The archive is read, its weights loaded and its reward function
    validated by a checker (``training.checkers``). A model that arrives with its weights is
    imported at once; one that would train is previewed first (``imports.import_start``), and
    created, its training queued, once the racer confirms (the archive kept meanwhile, not sent
    again). An attempt that has to be corrected keeps the racer's archive (unless the archive
    itself was refused), so the next one need not choose it again."""
    if request.method != "POST":
        return await sync_to_async(_model_import_blank)(request)
    attempt = await sync_to_async(_ModelImportAttempt)(request)  # the upload is read to disk here
    if attempt.work is not None:
        try:
            attempt.outcome = await checkers.run(attempt.work, racer=(await request.auser()).pk)
        except (Refused, *CHECK_FAILURES) as error:
            attempt.outcome = error
    return await sync_to_async(attempt.respond)()


def _model_import_blank(request: HttpRequest) -> HttpResponse:
    """The form, with the archive kept for the racer's next attempt, if one waits."""
    kept = kept_uploads.upload_held(racer=request.user)
    initial = {"kept": kept.token} if kept else {}
    form = ModelImportForm(owner=request.user, kept=kept, initial=initial)
    return render(request, "training/model_import.html", {"form": form})


@login_required
@require_POST
def model_import_cancel(request: HttpRequest) -> HttpResponse:
    """Delete the archive kept for the racer's import (a preview or a form to correct)."""
    kept = kept_uploads.upload_discard(racer=request.user)
    if kept is not None:
        messages.success(request, f"Cancelled: {kept.filename} is deleted, nothing was imported.")
    return redirect("training:model-import")


class _ModelImportAttempt:
    """A posted import, or its preview confirmed (``confirm``): the form and the racer's limit
    (``work``: the import, for a checker, when both allow it), then the page its outcome makes."""

    def __init__(self, request: HttpRequest) -> None:
        self.request = request
        self.work = None
        self.outcome: imports.Imported | imports.ImportPreview | Exception | None = None
        self.kept = kept_uploads.upload_kept(racer=request.user, token=request.POST.get("kept", ""))
        self.confirm = ModelImportConfirmForm(request.POST) if "confirm" in request.POST else None
        posted = (
            (request.POST, request.FILES)
            if self.confirm is None
            else ({"kept": request.POST.get("kept", "")},)
        )
        self.form = ModelImportForm(*posted, owner=request.user, kept=self.kept)
        if self.confirm is not None:
            self.form.is_valid()  # for the page to go back to: the kept archive, or a choice
        # Counted at once against both, so that parallel posts count each other; given back to
        # the one its outcome does not count against (_import_counted).
        self.held = ratelimits.hold(request, "import", "import-refused")
        self.limited = self.held.limited
        if self.limited:
            ratelimits.refuse(self.form, self.limited)
        elif self.confirm is not None and self.kept is None:
            self.form.add_error(None, KEPT_GONE)
        elif self.confirm is not None:
            confirmed = self.confirm.is_valid()  # else the preview again, with what to correct
            self.work = self._work(None, "", changes=self.confirm.changes(), confirmed=confirmed)
        elif self.form.is_valid():
            data = self.form.cleaned_data
            self.work = self._work(data["archive"], data["name"])

    def _work(self, upload, name: str, **step):
        owner, kept = self.request.user, self.kept

        def work() -> imports.Imported | imports.ImportPreview:
            with nullcontext(upload) if upload else kept_uploads.upload_open(kept) as archive:
                return imports.import_start(owner=owner, archive=archive, name=name, **step)

        return work

    def respond(self) -> HttpResponse:
        request, form, outcome = self.request, self.form, self.outcome
        if self.limited:
            form.keep(self.kept)  # the racer tries again later with the archive they chose
            return render(request, "training/model_import.html", {"form": form}, status=429)
        _import_counted(self.held, outcome)
        refused = False
        if isinstance(outcome, imports.Imported):
            kept_uploads.upload_discard(racer=request.user)
            messages.success(
                request,
                _imported_message(outcome.model)
                + (
                    " “From its import” below says what the import rebuilt or left out."
                    if outcome.model.import_notes
                    else ""
                ),
            )
            return redirect("training:model-detail", pk=outcome.model.pk)
        upload = request.FILES.get("archive") if self.confirm is None else None
        if isinstance(outcome, imports.ImportPreview):
            return self._preview(outcome, upload)
        if isinstance(outcome, imports.ImportRefused):
            form.add_error("archive", str(outcome))
            refused = True
        elif isinstance(outcome, configuration.Invalid):
            _import_errors(form, outcome.errors)
            refused = not set(outcome.errors) <= imports.PREVIEW_PROBLEMS  # else the archive's
        elif isinstance(outcome, Exception):
            form.add_error(None, _check_failed(outcome))
        if refused or ("archive" in form.errors and upload is not None):
            kept_uploads.upload_discard(racer=request.user)  # the racer must choose another
            form.keep(None)
        elif upload is not None:
            form.keep(self._keep(upload))
        elif self.confirm is not None:
            form.keep(self.kept)
        response = render(request, "training/model_import.html", {"form": form}, status=400)
        if isinstance(outcome, CHECK_FAILURES):
            return _check_refused(response, outcome)
        return response

    def _preview(self, preview: imports.ImportPreview, upload) -> HttpResponse:
        """What the import would create, to confirm or change: the archive kept for it."""
        request = self.request
        kept = self.kept
        if upload is not None:
            try:
                kept = kept_uploads.upload_keep(racer=request.user, upload=upload)
            except kept_uploads.UploadNotKept as refused:
                return self._not_kept(refused)
        confirm = self.confirm
        if confirm is None:
            confirm = ModelImportConfirmForm.of(preview, kept)
        else:
            confirm.add_problems(preview.problems)
        settings = preview.settings
        shown, _ = training_settings_shown(
            algorithm=settings["algorithm"], stored=settings["hyperparameters"], max_minutes=0
        )
        context = {
            "form": self.form,
            "preview": preview,
            "confirm": confirm,
            "kept": kept,
            "hyperparameters": [row for row in shown if row.key],
            "tracks": selectors.tracks_available(),
            "allowance": selectors.allowance_for(racer=request.user),
        }
        status = 400 if confirm.errors else 200
        return render(request, "training/model_import.html", context, status=status)

    def _keep(self, upload) -> KeptUpload | None:
        """``upload`` kept for the next attempt, or its refusal said by the archive."""
        try:
            return kept_uploads.upload_keep(racer=self.request.user, upload=upload)
        except kept_uploads.UploadNotKept as refused:
            self.form.add_error("archive", str(refused))
            return None

    def _not_kept(self, refused: kept_uploads.UploadNotKept) -> HttpResponse:
        """The form again (the name as typed), saying why the archive to confirm is not kept."""
        form = self.form
        form.add_error("archive", str(refused))
        form.keep(None)
        status = 400 if refused.retry_after is None else 503
        response = render(self.request, "training/model_import.html", {"form": form}, status=status)
        if refused.retry_after is not None:
            response["Retry-After"] = str(refused.retry_after)
        return response


KEPT_GONE = (
    f"The archive you uploaded is no longer kept (it is kept for "
    f"{KEPT_FOR.total_seconds() / 3600:g} hour after you upload it, until you import it, "
    "cancel or log out): choose it again."
)


def _imported_message(model: RLModel) -> str:
    """What the import created, said as the model page says it."""
    if model.status != RLModel.Status.READY:
        return (
            f"Imported {model.name}; its training is queued: up to {model.max_minutes} min on "
            f"{model.track}."
        )
    if model.trainable:
        return f"Imported {model.name}: it is ready to evaluate, race, clone or download."
    return (
        f"Imported {model.name}: a driving model without training history, ready to evaluate, "
        "race and download. It came from a car archive, with no reward function: it cannot "
        "train or be cloned."
    )


def _import_counted(held: ratelimits.Held, outcome: object) -> None:
    """Count a posted import, held against both of the racer's import limits, against one: one
    that arrived against "import"; any other attempt (refused, or a preview to confirm) against
    the looser "import-refused", so that correcting an archive does not use up the hour's
    imports; a check that could not run counts against neither."""
    if isinstance(outcome, imports.Imported):
        held.give_back("import-refused")
    elif isinstance(outcome, CHECK_FAILURES):
        held.give_back("import", "import-refused")
    else:
        held.give_back("import")


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


EVALUATION_FILES = {
    artifacts.EVALUATION_VIDEO: "Video (WebM)",
    artifacts.EVALUATION_TRACE: "Simulation trace (CSV)",
    artifacts.EVALUATION_METRICS: "Evaluation metrics (JSON)",
}


@login_required
def evaluation_detail(request: HttpRequest, pk: int, evaluation: int) -> HttpResponse:
    job = _get_evaluation_for_user(request, pk, evaluation)
    prefix = artifacts.path(job.model, artifacts.evaluation_prefix(job))
    ended = (EvaluationJob.Status.COMPLETED, EvaluationJob.Status.CANCELED)
    files = [
        (name, label)
        for name, label in EVALUATION_FILES.items()
        if job.status in ended and default_storage.exists(prefix + name)
    ]
    stoppable = job.status in (
        EvaluationJob.Status.QUEUED,
        EvaluationJob.Status.INITIALIZING,
        EvaluationJob.Status.IN_PROGRESS,
    )
    return render(
        request,
        "training/evaluation_detail.html",
        {
            "model": job.model,
            "evaluation": job,
            "trials": list(job.trial_rows.all()),
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
    if name not in EVALUATION_FILES:
        raise Http404("No such file")
    stored = artifacts.path(job.model, artifacts.evaluation_prefix(job) + name)
    if not default_storage.exists(stored):
        raise Http404("No such file")
    video = name == artifacts.EVALUATION_VIDEO
    filename = f"{job.model.name}-evaluation-{job.pk}-{name.replace('/', '-')}"
    content_type = "video/webm" if video else None
    return artifacts.download(
        request, stored, filename, attachment=not video, content_type=content_type
    )
