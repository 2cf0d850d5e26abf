"""The Analysis tab of a model (its training) and of an evaluation or race entry: the page, and
the data its script asks for as the racer picks iterations, outcomes and episodes."""

from __future__ import annotations

from django.contrib.auth.decorators import login_required
from django.http import Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import get_object_or_404, render
from django.urls import reverse
from django.views.decorators.http import require_GET, require_POST

from analysis import selectors, services, traces
from analysis.forms import RescoreForm
from analysis.models import Rescoring
from analysis.records import Source
from common import ratelimits
from common.refusals import WHOLE
from training.models import EvaluationJob, RLModel


def _source(request: HttpRequest, pk: int, evaluation: int | None) -> Source:
    """The racer's own model's recorded driving, or 404."""
    model = get_object_or_404(RLModel.objects.select_related("track"), pk=pk, owner=request.user)
    if evaluation is not None:
        found = get_object_or_404(
            EvaluationJob.objects.select_related("model", "track"), pk=evaluation, model=model
        )
        return Source.of_evaluation(found)
    job = model.latest_job
    if job is None:
        raise Http404("This model has not been trained here.")
    return Source.of_job(job)


def _base(source: Source) -> str:
    if source.evaluation is not None:
        return reverse("analysis:evaluation", args=[source.model.pk, source.evaluation.pk])
    return reverse("analysis:model", args=[source.model.pk])


@login_required
@require_GET
def page(request: HttpRequest, pk: int, evaluation: int | None = None) -> HttpResponse:
    source = _source(request, pk, evaluation)
    unreadable = source.ensure()
    overview = selectors.overview(source)
    numbers = [row["iteration"] for row in overview["iterations"]] or [0]
    services.rescorings_lapsed(owner=request.user)
    rescorings = Rescoring.objects.filter(
        job=source.job, evaluation=source.evaluation, owner=request.user
    ).order_by("-created_at")[:5]
    return render(
        request,
        "analysis/analysis.html",
        {
            "model": source.model,
            "evaluation": source.evaluation,
            "submission": getattr(source.evaluation, "submission", None),
            "overview": overview,
            "first_iteration": numbers[0],
            "last_iteration": numbers[-1],
            "base": _base(source),
            "unreadable": unreadable,
            "multi_track": bool(source.model.extra_tracks) and source.evaluation is None,
            "form": RescoreForm(
                owner=request.user,
                model=source.model,
                initial={"reward_function": source.model.reward_function},
            ),
            "rescorings": rescorings,
        },
    )


@login_required
@require_GET
def data(request: HttpRequest, pk: int, evaluation: int | None = None) -> JsonResponse:
    source = _source(request, pk, evaluation)
    choice = _choice(request, source)
    return JsonResponse(selectors.picked(source, choice))


@login_required
@require_GET
def points(request: HttpRequest, pk: int, evaluation: int | None = None) -> HttpResponse:
    source = _source(request, pk, evaluation)
    rescoring = None
    asked = request.GET.get("rescoring", "")
    if asked.isascii() and asked.isdecimal() and len(asked) <= 18:  # a row's id, or nothing
        rescoring = Rescoring.objects.filter(
            pk=int(asked),
            owner=request.user,
            status=Rescoring.Status.DONE,
            job=source.job,
            evaluation=source.evaluation,
        ).first()
    body = selectors.points(source, _choice(request, source), rescoring)
    response = HttpResponse(body, content_type="application/octet-stream")
    response["Cache-Control"] = "private, max-age=60"
    return response


def _choice(request: HttpRequest, source: Source) -> selectors.Choice:
    iterations = list(source.summaries().values_list("iteration", flat=True))
    return selectors.Choice.parse(request.GET, iterations=iterations)


@login_required
@require_GET
def episode(request: HttpRequest, pk: int, evaluation: int | None = None) -> JsonResponse:
    source = _source(request, pk, evaluation)
    try:
        iteration, number = int(request.GET["iteration"]), int(request.GET["episode"])
    except (KeyError, ValueError):
        return JsonResponse({"error": "Choose an episode from the table."}, status=400)
    known = 0 <= iteration < 2**31 and source.summaries().filter(iteration=iteration).exists()
    if not known:  # before its name reaches the storage
        return JsonResponse({"error": "That iteration was not recorded."}, status=404)
    try:
        found = selectors.episode(source, iteration, number)
    except traces.Unreadable as error:
        return JsonResponse({"error": str(error)}, status=404)
    if found is None:
        return JsonResponse(
            {"error": f"Iteration {iteration} has no episode {number}."}, status=404
        )
    return JsonResponse(found)


@login_required
@require_POST
def rescore(request: HttpRequest, pk: int, evaluation: int | None = None) -> JsonResponse:
    source = _source(request, pk, evaluation)
    form = RescoreForm(request.POST, owner=request.user, model=source.model)
    limited = ratelimits.over(request, "rescore")
    if limited is not None:
        return JsonResponse({"errors": {WHOLE: [{"message": str(limited)}]}}, status=429)
    if not form.is_valid():
        return JsonResponse({"errors": form.errors.get_json_data(escape_html=False)}, status=400)
    try:
        rescoring = services.rescoring_create(
            source=source, owner=request.user, **form.cleaned_data
        )
    except services.RescoringRefused as refused:
        errors = {name: [{"message": message}] for name, message in refused.errors.items()}
        return JsonResponse({"errors": errors}, status=400)
    return JsonResponse(_rescoring(rescoring, source), status=202)


@login_required
@require_GET
def rescoring(
    request: HttpRequest, pk: int, rescoring: int, evaluation: int | None = None
) -> JsonResponse:
    source = _source(request, pk, evaluation)
    services.rescorings_lapsed(owner=request.user)
    found = get_object_or_404(
        Rescoring, pk=rescoring, owner=request.user, job=source.job, evaluation=source.evaluation
    )
    return JsonResponse(_rescoring(found, source))


def _rescoring(rescoring: Rescoring, source: Source) -> dict:
    return {
        "id": rescoring.pk,
        "url": f"{_base(source)}rescorings/{rescoring.pk}/",
        "status": rescoring.status,
        "status_display": rescoring.get_status_display(),
        "place": selectors.rescoring_place(rescoring),  # re-scorings taken up before it
        "first": rescoring.first,
        "last": rescoring.last,
        "steps": rescoring.steps,
        "total_steps": rescoring.total_steps,
        "failure": rescoring.failure,
        "episodes": rescoring.episodes if rescoring.status == Rescoring.Status.DONE else {},
        "log": rescoring.log,
    }
