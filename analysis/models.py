"""What the analysis keeps: each recorded trace's summary, and the re-scorings racers ask for."""

from __future__ import annotations

from django.conf import settings
from django.db import models

from training.models import EvaluationJob, TrainingJob


class TraceSummary(models.Model):
    """The summary of one recorded simulation trace (``analysis.summaries``): a training
    iteration's, or an evaluation's (a race entry's included)."""

    job = models.ForeignKey(
        TrainingJob, null=True, blank=True, on_delete=models.CASCADE, related_name="summaries"
    )
    iteration = models.PositiveIntegerField(default=0, help_text="1, 2, ...; 0 for an evaluation.")
    evaluation = models.OneToOneField(
        EvaluationJob, null=True, blank=True, on_delete=models.CASCADE, related_name="summary"
    )
    version = models.PositiveSmallIntegerField(help_text="Of the summary's format.")
    episodes = models.JSONField(default=list)
    marks = models.JSONField(default=list)
    actions = models.BinaryField(default=b"")
    points = models.BinaryField(default=b"")
    steps = models.PositiveIntegerField(default=0)
    created_at = models.DateTimeField(auto_now_add=True)

    class Meta:
        constraints = [
            models.UniqueConstraint(
                fields=["job", "iteration"],
                condition=models.Q(job__isnull=False),
                name="one_summary_per_iteration",
            ),
            models.CheckConstraint(
                condition=models.Q(job__isnull=True) ^ models.Q(evaluation__isnull=True),
                name="summary_of_a_job_or_an_evaluation",
            ),
        ]

    def __str__(self) -> str:
        if self.job_id:
            return f"job {self.job_id}, iteration {self.iteration}"
        return f"evaluation {self.evaluation_id}"


class Rescoring(models.Model):
    """Another reward function run over recorded traces, to compare with the one trained with."""

    class Status(models.TextChoices):
        QUEUED = "QUEUED", "Queued"
        RUNNING = "RUNNING", "Running"
        DONE = "DONE", "Done"
        FAILED = "FAILED", "Failed"

    owner = models.ForeignKey(settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="+")
    job = models.ForeignKey(
        TrainingJob, null=True, blank=True, on_delete=models.CASCADE, related_name="rescorings"
    )
    evaluation = models.ForeignKey(
        EvaluationJob, null=True, blank=True, on_delete=models.CASCADE, related_name="rescorings"
    )
    reward_function = models.TextField()
    first = models.PositiveIntegerField(default=0, help_text="The iterations scored: first..last.")
    last = models.PositiveIntegerField(default=0)
    status = models.CharField(max_length=8, choices=Status.choices, default=Status.QUEUED)
    created_at = models.DateTimeField(auto_now_add=True)
    started_at = models.DateTimeField(null=True, blank=True, help_text="When a worker took it up.")
    finished_at = models.DateTimeField(null=True, blank=True)
    failure = models.TextField(blank=True, help_text="Why it failed, in the racer's words.")
    steps = models.PositiveIntegerField(default=0, help_text="Steps scored so far.")
    total_steps = models.PositiveIntegerField(default=0)
    # {"<iteration>": [[episode number, total reward], ...]}
    episodes = models.JSONField(default=dict)
    # float32: the new reward of each point of the summaries first..last, in that order
    points = models.BinaryField(default=b"")
    point_counts = models.JSONField(default=dict, help_text="{iteration: its summary's points}")
    log = models.JSONField(default=list, help_text="The first lines the reward function printed.")

    class Meta:
        constraints = [
            models.CheckConstraint(
                condition=models.Q(job__isnull=True) ^ models.Q(evaluation__isnull=True),
                name="rescoring_of_a_job_or_an_evaluation",
            ),
        ]

    def __str__(self) -> str:
        return f"re-scoring {self.pk}"
