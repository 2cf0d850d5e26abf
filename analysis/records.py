"""Where a model's recorded driving is, and its summaries: a ``Source`` is a training job or an
evaluation (a race entry's included), with its track and its stored traces."""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

from django.core.files.storage import default_storage
from django.db.models import QuerySet

from analysis import summaries, traces
from analysis.models import TraceSummary
from simulator import tracks
from training import artifacts
from training.models import EvaluationJob, RLModel, TrainingJob


@functools.lru_cache(maxsize=32)
def track_driven(name: str, direction: str, route: str | None) -> tracks.Track:
    """``simulator.tracks.driven``, kept per process: a track's geometry (its borders' polygon,
    its waypoints' tree) is built once for every page and re-scoring that reads it."""
    return tracks.driven(name, direction, route)


@dataclass(frozen=True)
class Source:
    """Recorded driving: a training job's iterations, or an evaluation's trials."""

    model: RLModel
    job: TrainingJob | None = None
    evaluation: EvaluationJob | None = None

    @classmethod
    def of_job(cls, job: TrainingJob) -> Source:
        return cls(model=job.model, job=job)

    @classmethod
    def of_evaluation(cls, evaluation: EvaluationJob) -> Source:
        return cls(model=evaluation.model, evaluation=evaluation)

    @functools.cached_property
    def track(self) -> tracks.Track:
        """The track as the recorded driving drove it, on the route file it drove (numbers only:
        no engine is built): a DeepRacer for Cloud import's own, not the console's."""
        where = self.evaluation or self.model  # an evaluation drives its own track, its way
        name = where.track.name
        return track_driven(name, where.direction, self.model.route_on(name))

    @property
    def actions(self) -> int | None:
        """How many discrete actions the model has; None for a continuous action space."""
        return len(self.model.action_space) if self.model.action_space_type == "discrete" else None

    def trace_name(self, iteration: int) -> str:
        if self.evaluation is not None:
            relative = artifacts.evaluation_prefix(self.evaluation) + artifacts.EVALUATION_TRACE
        else:
            relative = artifacts.training_trace(iteration)
        return artifacts.path(self.model, relative)

    def iterations(self) -> list[int]:
        """The iterations with a recorded trace (an evaluation's one: 0)."""
        if self.evaluation is not None:
            return [0] if default_storage.exists(self.trace_name(0)) else []
        folder = self.trace_name(1).rsplit("/", 1)[0]
        try:
            _, files = default_storage.listdir(folder)  # one listing, also of a bucket
        except FileNotFoundError:
            return []
        found = (re.fullmatch(r"(\d+)-iteration\.csv", name) for name in files)
        return sorted(int(match.group(1)) + 1 for match in found if match)

    def read(self, iteration: int) -> traces.Steps:
        """The trace of ``iteration``; ``traces.Unreadable`` when it is missing or broken."""
        try:
            document = artifacts.read(self.trace_name(iteration))
        except FileNotFoundError:
            raise traces.Unreadable(
                "The simulation trace of this iteration was not kept."
            ) from None
        return traces.read(document)

    def summaries(self) -> QuerySet[TraceSummary]:
        if self.evaluation is not None:
            return TraceSummary.objects.filter(evaluation=self.evaluation)
        return TraceSummary.objects.filter(job=self.job)

    def ensure(self) -> list[int]:
        """Summarise what was recorded and not summarised yet (a trace recorded before the
        analysis existed, or whose summary failed); the iterations that could not be read."""
        current = set(
            self.summaries().filter(version=summaries.VERSION).values_list("iteration", flat=True)
        )
        found = self.iterations()
        run = self.evaluation or self.job
        if run is not None and run.is_active:  # its newest trace may be half-written still:
            found = found[:-1]  # the trainer (or evaluation) summarises it once it is whole
        unreadable = []
        for iteration in found:
            if iteration in current:
                continue
            try:
                steps = self.read(iteration)
            except traces.Unreadable:
                unreadable.append(iteration)
                continue
            save(self, iteration, steps)
        return unreadable


def save(source: Source, iteration: int, steps: traces.Steps) -> TraceSummary:
    summary = summaries.summarize(steps, waypoints=len(source.track.centre), actions=source.actions)
    fields = {
        "version": summaries.VERSION,
        "episodes": summary.episodes,
        "marks": summary.marks,
        "actions": summary.actions,
        "points": summary.points,
        "steps": summary.steps,
    }
    if source.evaluation is not None:
        row, _ = TraceSummary.objects.update_or_create(
            evaluation=source.evaluation, defaults=fields
        )
    else:
        row, _ = TraceSummary.objects.update_or_create(
            job=source.job, iteration=iteration, defaults=fields
        )
    return row


def summarize_document(
    document: str | bytes,
    *,
    job: TrainingJob | None = None,
    iteration: int = 0,
    evaluation: EvaluationJob | None = None,
) -> TraceSummary:
    """Summarise a trace just recorded, for ``job``'s ``iteration`` or for ``evaluation``."""
    source = Source.of_evaluation(evaluation) if evaluation else Source.of_job(job)
    return save(source, iteration, traces.read(document))
