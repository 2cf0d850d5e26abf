"""A model's archives in and out, as pages: its downloads (the physical car's, ONNX, the virtual
model's and the logs laid out as DeepRacer's) and the import, with its preview to confirm and the
archive kept meanwhile (``archives.kept_uploads``). The archives themselves are built and read
by ``exports``, ``logs_archive`` and ``imports``; these views parse the request, call them and
render.
"""

from __future__ import annotations

from contextlib import nullcontext

from asgiref.sync import sync_to_async
from django.contrib import messages
from django.contrib.admin.views.decorators import staff_member_required
from django.contrib.auth.decorators import login_required
from django.http import HttpRequest, HttpResponse
from django.shortcuts import redirect, render
from django.views.decorators.http import require_POST, require_safe

from archives import drfc_bucket, exports, imports, kept_uploads, logs_archive
from archives.forms import BucketImportForm, ModelImportConfirmForm, ModelImportForm
from archives.models import KeptUpload
from common import ratelimits
from common.refusals import Refused
from training import artifacts, checkers, configuration, selectors
from training.forms import training_settings_shown
from training.models import RLModel


def _get_model_for_user(request: HttpRequest, pk: int) -> RLModel:
    return selectors.model_of_racer(racer=request.user, pk=pk)


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
    try:
        return logs_archive.download(request, model)
    except logs_archive.LogsRefused as refused:
        messages.error(request, str(refused))
        return redirect("training:model-detail", pk=model.pk)


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
        except (Refused, *checkers.FAILURES) as error:
            attempt.outcome = error
    return await sync_to_async(attempt.respond)()


def _model_import_blank(request: HttpRequest) -> HttpResponse:
    """The form, with the archive kept for the racer's next attempt, if one waits."""
    kept = kept_uploads.upload_held(racer=request.user)
    initial = {"kept": kept.token} if kept else {}
    form = ModelImportForm(owner=request.user, kept=kept, initial=initial)
    return render(request, "archives/model_import.html", {"form": form})


@staff_member_required
async def model_import_bucket(request: HttpRequest) -> HttpResponse:
    """Staff import a model from DeepRacer for Cloud's bucket (``archives.drfc_bucket``), for
    themselves or a racer: read and imported by a checker, as an uploaded archive is."""
    staff = await request.auser()
    form = BucketImportForm(request.POST or None, staff=staff)
    if request.method == "POST" and await sync_to_async(form.is_valid)():
        data = form.cleaned_data

        def work() -> imports.Imported:
            return drfc_bucket.import_from_bucket(
                owner=data["racer"], url=data["url"], name=data["name"]
            )

        try:
            imported = await checkers.run(work, racer=staff.pk)
        except (Refused, *checkers.FAILURES) as error:
            await sync_to_async(_bucket_refused)(form, error)
        else:
            model = imported.model
            whose = "" if model.owner_id == staff.pk else f" for {data['racer'].get_username()}"
            await sync_to_async(messages.success)(
                request, f"{_imported_message(model)} (from {data['url']}{whose})"
            )
            if model.owner_id == staff.pk:
                return redirect("training:model-detail", pk=model.pk)
            return redirect("archives:model-import-bucket")
    status = 400 if form.is_bound else 200
    return await sync_to_async(render)(
        request, "archives/model_import_bucket.html", {"form": form}, status=status
    )


def _bucket_refused(form: BucketImportForm, error: Exception) -> None:
    if isinstance(error, configuration.Invalid):
        _import_errors(form, error.errors)
    elif isinstance(error, Refused):
        form.add_error("url", str(error))
    else:
        form.add_error(None, checkers.failure_words(error))


@login_required
@require_POST
def model_import_cancel(request: HttpRequest) -> HttpResponse:
    """Delete the archive kept for the racer's import (a preview or a form to correct)."""
    kept = kept_uploads.upload_discard(racer=request.user)
    if kept is not None:
        messages.success(request, f"Cancelled: {kept.filename} is deleted, nothing was imported.")
    return redirect("archives:model-import")


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
        # the one its outcome does not count against (imports.attempt_counted).
        self.held = ratelimits.hold(request, "import", "import-refused")
        self.limited = self.held.limited
        if self.limited:
            ratelimits.refuse(self.form, self.limited)
        elif self.confirm is not None and self.kept is None:
            self.form.add_error(None, kept_uploads.KEPT_GONE)
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
            return render(request, "archives/model_import.html", {"form": form}, status=429)
        imports.attempt_counted(self.held, outcome)
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
            form.add_error(None, checkers.failure_words(outcome))
        if refused or ("archive" in form.errors and upload is not None):
            kept_uploads.upload_discard(racer=request.user)  # the racer must choose another
            form.keep(None)
        elif upload is not None:
            form.keep(self._keep(upload))
        elif self.confirm is not None:
            form.keep(self.kept)
        response = render(request, "archives/model_import.html", {"form": form}, status=400)
        if isinstance(outcome, checkers.FAILURES):
            return checkers.failure_response(response, outcome)
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
        return render(request, "archives/model_import.html", context, status=status)

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
        response = render(self.request, "archives/model_import.html", {"form": form}, status=status)
        if refused.retry_after is not None:
            response["Retry-After"] = str(refused.retry_after)
        return response


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


def _import_errors(form: ModelImportForm | BucketImportForm, errors: dict[str, str]) -> None:
    """The settings an archive brought that cannot be used, each where the racer can act."""
    for setting, message in errors.items():
        if setting == "name":
            form.add_error("name", message)
        else:  # a setting the archive brought: say which
            label = setting.split(".")[-1].replace("_", " ").capitalize()
            form.add_error(None, f"{label}: {message}")
