"""A racer's evaluations in the API: start one, list a model's, one with its trials, stop.

The evaluate page's rules, through its services: the settings checked as the page checks them
(``configuration.check_evaluation``: DeepRacer's defaults for what is left out, the model's track
unless another is named), the racer's ``evaluate`` limit and their evaluations at once; the
model must be ready and trained. Its video, trace and metrics are the evaluation page's files.
"""

from __future__ import annotations

from datetime import datetime

from ninja import Router, Schema, Status

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError, counted
from api.owned import own_model
from api.schemas import REFUSED, named_choices
from training import artifacts, services
from training.models import EvaluationJob, EvaluationTrial

router = Router()
EvaluationStatus = named_choices(EvaluationJob.Status, "EvaluationStatus")


class EvaluationIn(Schema):
    """What the evaluate page sets; each left out takes its default there."""

    track: str | None = None
    direction: str | None = None
    race_type: str | None = None
    trials: int | None = None
    continuous_laps: bool | None = None
    off_track_penalty: float | None = None
    crash_penalty: float | None = None
    max_resets: int | None = None
    checkpoint: str | None = None
    domain_randomisation: bool | None = None
    seed: int | None = None


class TrialOut(Schema):
    number: int
    time_ms: int
    progress: float
    status: str
    off_tracks: int
    crashes: int
    resets: int
    penalty_ms: int


class EvaluationOut(Schema):
    id: int
    model: int
    status: EvaluationStatus
    track: str
    trials: int
    checkpoint: str
    checkpoint_iteration: int | None
    seed: int | None
    message: str
    failure_reason: str
    created_at: datetime
    finished_at: datetime | None


class EvaluationDetail(EvaluationOut):
    results: list[TrialOut]
    best_lap_ms: int | None


def _out(evaluation: EvaluationJob) -> dict:
    return {
        "id": evaluation.pk,
        "model": evaluation.model_id,
        "status": evaluation.status,
        "track": evaluation.track.name,
        "trials": evaluation.trials,
        "checkpoint": evaluation.checkpoint,
        "checkpoint_iteration": evaluation.checkpoint_iteration,
        "seed": evaluation.seed,
        "message": evaluation.message,
        "failure_reason": evaluation.failure_reason,
        "created_at": evaluation.created_at,
        "finished_at": evaluation.finished_at,
    }


def _own(request, model_id: int, evaluation_id: int) -> EvaluationJob:
    evaluation = (
        EvaluationJob.objects.select_related("track")
        .filter(pk=evaluation_id, model=own_model(request, model_id))
        .first()
    )
    if evaluation is None:
        raise ApiError(404, "not_found", f"Model {model_id} has no evaluation {evaluation_id}.")
    return evaluation


def _detail(evaluation: EvaluationJob) -> dict:
    trials: list[EvaluationTrial] = list(evaluation.trial_rows.all())
    return {**_out(evaluation), "results": trials, "best_lap_ms": evaluation.best_lap_ms}


@router.post("/{model_id}/evaluations", response={201: EvaluationDetail, **REFUSED})
def evaluation_create(request, model_id: int, body: EvaluationIn):
    """Evaluate one of your ready models, as its Evaluate page does: ``trials`` (3 to 5), the
    penalties, ``max_resets``, the ``best`` or ``last`` checkpoint, a track and race type other
    than its own; ``seed`` drives an earlier evaluation's trials again. The model is busy until
    it ends (409 meanwhile for another)."""
    need(request, TokenScope.TRAIN)
    model = own_model(request, model_id)
    counted(request, "evaluate")
    settings = body.dict(exclude_none=True)
    seed = settings.pop("seed", None)
    try:
        evaluation = services.evaluation_start(model=model, settings=settings, seed=seed)
    except services.EvaluationRefused as refused:
        raise ApiError(409, "refused", str(refused)) from None
    return Status(201, _detail(evaluation))


@router.get("/{model_id}/evaluations", response={200: list[EvaluationOut], **REFUSED})
def evaluations_list(request, model_id: int):
    """The model's evaluations, newest first (its races' included)."""
    need(request, TokenScope.READ)
    found = EvaluationJob.objects.select_related("track").filter(model=own_model(request, model_id))
    return [_out(evaluation) for evaluation in found.order_by("-created_at", "-pk")]


@router.get("/{model_id}/evaluations/{evaluation_id}", response={200: EvaluationDetail, **REFUSED})
def evaluation_detail(request, model_id: int, evaluation_id: int):
    """One evaluation with each trial's result, as its page's results table shows them."""
    need(request, TokenScope.READ)
    return _detail(_own(request, model_id, evaluation_id))


@router.post(
    "/{model_id}/evaluations/{evaluation_id}/stop", response={200: EvaluationDetail, **REFUSED}
)
def evaluation_stop(request, model_id: int, evaluation_id: int):
    """Stop the evaluation, as its page's Stop does: one still waiting is canceled; a running one
    ends with the trials it finished. A race's evaluation drives to its end (409)."""
    need(request, TokenScope.TRAIN)
    evaluation = _own(request, model_id, evaluation_id)
    try:
        evaluation = services.evaluation_stop(evaluation=evaluation)
    except services.EvaluationRefused as refused:
        raise ApiError(409, "refused", str(refused)) from None
    return _detail(evaluation)


@router.get(
    "/{model_id}/evaluations/{evaluation_id}/files/{path:name}", response={200: None, **REFUSED}
)
def evaluation_file(request, model_id: int, evaluation_id: int, name: str):
    """The evaluation's ``video.webm``, its trace (``evaluation-simtrace/0-iteration.csv``) or
    its metrics (``metrics/evaluation_metrics.json``), as its page offers them; 404 until
    written."""
    need(request, TokenScope.READ)
    evaluation = _own(request, model_id, evaluation_id)
    try:
        return artifacts.evaluation_download(request, evaluation, name)
    except FileNotFoundError:
        raise ApiError(
            404, "not_found", f"Evaluation {evaluation_id} has no file {name!r} (yet)."
        ) from None
