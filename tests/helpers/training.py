"""A model's settings, as a service takes them and as the create-model form posts them; training
jobs, queued or in progress, and waiting on them."""

import json
import re
from datetime import timedelta
from pathlib import Path

import pytest
from django.urls import reverse
from django.utils import timezone

from rl import hyperparameters
from tests.services import parent_of, wait_for
from training import configuration
from training.models import RLModel, TrainingJob
from training.rewards import EXAMPLES

TINY_PPO = {"batch_size": 32, "num_epochs": 3, "num_episodes_between_training": 5}


def settings(**changes) -> dict:
    base = {
        "name": "tiny-oval",
        "track": "pitlane-oval",
        "sensors": ["FRONT_FACING_CAMERA"],
        "algorithm": "clipped_ppo",
        "hyperparameters": {**hyperparameters.defaults("clipped_ppo"), **TINY_PPO},
        "max_minutes": 10,
        "reward_function": EXAMPLES[0].source,
    }
    return {**base, **changes}


def field_html(page: str, name: str) -> str:
    """The input (or select) a page shows for the field ``name``."""
    return re.search(rf'<(?:input|select)[^>]*name="{name}"[^>]*>', page)[0]


def field_words(page: str, name: str) -> tuple[str, str]:
    """The label and the help a page shows for the field ``name`` (``includes/field.html``)."""
    start = page.rindex('<div class="field', 0, page.index(f'name="{name}"'))
    block = page[start : page.find('<div class="field"', start + 1)]
    label = re.search(r"<label[^>]*>(?:<input[^>]*>)?(.*?)</label>", block, re.S)[1]
    help_ = re.search(r'<div class="field-help">(.*?)</div>', block, re.S)
    return label.strip(), help_[1] if help_ else ""


def form_data(**changes) -> dict:
    """The create-model form as the page posts it, with ``changes``."""
    data = {
        "name": "first-model",
        "description": "",
        "track": "rookie-loop",
        "direction": "counterclockwise",
        "race_type": "TIME_TRIAL",
        "camera": "FRONT_FACING_CAMERA",
        "lidar": "",
        "network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        "action_space_type": "discrete",
        "actions": json.dumps([{"steering_angle": a, "speed": 1} for a in (-20, 0, 20)]),
        "steering_low": -30,
        "steering_high": 30,
        "speed_low": 1,
        "speed_high": 2,
        "algorithm": "clipped_ppo",
        "max_minutes": 60,
        "workers": 1,
        "reward_function": EXAMPLES[0].source,
    }
    for algorithm, values in (
        ("clipped_ppo", hyperparameters.defaults("clipped_ppo")),
        ("sac", hyperparameters.defaults("sac")),
    ):
        data.update({f"{algorithm}__{name}": value for name, value in values.items()})
    return {**data, **changes}


def post(client, racer, url=None, **changes):
    """``racer``, logged in, posts the create-model form (or the form at ``url``)."""
    client.force_login(racer)
    return client.post(url or reverse("training:model-create"), form_data(**changes))


def reload(job: TrainingJob) -> TrainingJob:
    return TrainingJob.objects.select_related("model").get(pk=job.pk)


def wait_for_job(job: TrainingJob, condition, what: str, timeout: float = 240) -> TrainingJob:
    """Wait until ``condition(job)``; a job that fails meanwhile fails the test with its log."""

    def log_of(current: TrainingJob) -> str:
        return "\n".join(f"{line.at:%H:%M:%S} {line.text}" for line in current.log_lines.all())

    def reached() -> bool:
        current = reload(job)
        if current.status == TrainingJob.Status.FAILED:
            pytest.fail(f"the job failed: {current.failure_reason}\n{log_of(current)}")
        return condition(current)

    try:
        wait_for(reached, what, timeout=timeout)
    except TimeoutError as error:
        pytest.fail(f"{error}; the job's log:\n{log_of(reload(job))}")
    return reload(job)


def queued_job(owner) -> TrainingJob:
    """A job saved without enqueueing its trainer: one still waiting for a free worker."""
    clean = configuration.check(settings(), owner=owner, validate_reward=False)
    return TrainingJob.objects.create(model=RLModel.objects.create(owner=owner, **clean.row()))


def trainer_initializing(owner):
    """The trainer (``jobs.trainer.Trainer``) of a new job of ``owner``'s, as its run begins: the
    lease held, the job's keys in Redis, INITIALIZING, its workers just checked and none started
    (its tests drive ``_turn`` and the workers' beats themselves)."""
    from jobs import trainer
    from training import leases

    job = leases.lease_acquire(job_id=queued_job(owner).pk, owner="this-run")
    run = trainer.Trainer(job, start_rollouts=lambda job, slot: None)
    run.channel.start(job.attempt)
    run.training_message, run.first_run = "Training with 1 simulation worker", False
    run.worker_checks.due()  # the workers were just checked
    leases.move(job, TrainingJob.Status.INITIALIZING)
    return run


def sandbox_children() -> dict[int, int]:
    """The running sandbox children: {pid: their zygote's pid}. Their reward processes, forks of
    theirs, are left out."""
    found = {}
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            parent = parent_of(int(entry.name))
            if b"sandbox.zygote" in Path(f"/proc/{parent}/cmdline").read_bytes():
                found[int(entry.name)] = parent
        except (OSError, ValueError, IndexError):  # a process that ended as it was read
            continue
    return found


def training_job(owner, *, seconds: float, ago: float, **fields) -> TrainingJob:
    """A job in progress whose trainer last measured ``seconds`` used, ``ago`` seconds ago."""
    clean = configuration.check(settings(name="clocked"), owner=owner, validate_reward=False)
    model = RLModel.objects.create(owner=owner, status=RLModel.Status.TRAINING, **clean.row())
    return TrainingJob.objects.create(
        model=model,
        status=TrainingJob.Status.IN_PROGRESS,
        attempt=1,
        lease_owner="trainer:1",
        training_seconds=seconds,
        clock_at=timezone.now() - timedelta(seconds=ago),
        iterations=3,
        **fields,
    )
