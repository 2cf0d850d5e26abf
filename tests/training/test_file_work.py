"""No file work inside a write transaction (issue 42, item 3): a clone's starting weights, an
import's files and a trainer's checkpoints are written to storage with no transaction open, and a
model row never points at files that are not there (a clone whose copy failed is ERROR, an
import whose files failed leaves nothing)."""

import io
import time
from datetime import timedelta

import pytest
from django.core.files.storage import FileSystemStorage, default_storage
from django.db import OperationalError
from django.utils import timezone

from archives import imports
from common import transactions
from console import recovery
from jobs import trainer
from rl.learner import Update
from rl.stopwatch import Stopwatch
from tests.helpers.archives import virtual_archive
from tests.helpers.models import STRAIGHT_AHEAD, ready_model, stored_objects
from tests.helpers.training import settings as training_settings
from training import artifacts, configuration, leases, services
from training.models import RLModel, TrainingJob

pytestmark = pytest.mark.django_db


@pytest.fixture
def storage_writes(monkeypatch) -> list[tuple[str, bool]]:
    """Each file saved to or deleted from storage: (its name, whether a transaction of the
    code's was open)."""
    seen, save, delete = [], FileSystemStorage._save, FileSystemStorage.delete

    def saved(storage, name, content):
        seen.append((name, transactions.in_transaction()))
        return save(storage, name, content)

    def deleted(storage, name):
        seen.append((name, transactions.in_transaction()))
        return delete(storage, name)

    monkeypatch.setattr(FileSystemStorage, "_save", saved)
    monkeypatch.setattr(FileSystemStorage, "delete", deleted)
    return seen


def clone_of(source: RLModel) -> RLModel:
    return services.model_create(
        owner=source.owner,
        validate_reward=False,
        settings=training_settings(name="clone", action_space=STRAIGHT_AHEAD, cloned_from=source),
    )


def test_a_clone_copies_its_sources_weights_after_its_rows_are_committed(
    alice, tracks, storage_writes, django_capture_on_commit_callbacks
):
    source = ready_model(alice)
    storage_writes.clear()
    with django_capture_on_commit_callbacks() as sends:
        clone = clone_of(source)
    copy = artifacts.path(clone, artifacts.CLONED_WEIGHTS)
    assert any(name.startswith(copy) for name, _ in storage_writes)
    assert not any(inside for _, inside in storage_writes)
    assert artifacts.read(copy) == artifacts.read(source.jobs.get().best_checkpoint)
    assert clone.status == RLModel.Status.QUEUED and len(sends) == 1  # its trainer, sent after


def test_a_clone_whose_weights_cannot_be_copied_fails_in_words_and_its_source_stays(
    alice, tracks, monkeypatch, django_capture_on_commit_callbacks
):
    source = ready_model(alice)
    best = source.jobs.get().best_checkpoint

    def storage_down(model, relative, data):
        raise OSError("No space left on device")

    monkeypatch.setattr(artifacts, "save", storage_down)
    with django_capture_on_commit_callbacks() as sends:
        clone = clone_of(source)
    clone.refresh_from_db()
    job = clone.jobs.get()
    assert clone.status == RLModel.Status.ERROR and job.status == TrainingJob.Status.FAILED
    assert job.failure_reason == (
        "The weights of the model it was cloned from could not be copied (storage failed), so "
        "it did not start training; delete it and clone that model again."
    )
    assert sends == []  # no trainer sent for it
    assert RLModel.objects.get(pk=source.pk).status == RLModel.Status.READY
    assert artifacts.read(best)


@pytest.mark.slow
def test_a_trainer_that_finds_no_copy_of_its_clones_weights_makes_it(alice, tracks, monkeypatch):
    # The request that created the clone died before it copied them: the job, sent again by
    # recovery.resend_lost, starts from the source's weights all the same.
    source = ready_model(alice)
    monkeypatch.setattr(services, "_clone_weights_start", lambda job, weights: True)
    clone = clone_of(source)
    copy = artifacts.path(clone, artifacts.CLONED_WEIGHTS)
    artifacts.default_storage.delete(copy)  # an earlier test's model of that id may have left one
    run = trainer.Trainer(leases.lease_acquire(job_id=clone.jobs.get().pk, owner="run"), None)
    run._build_learner()
    assert artifacts.read(copy) == artifacts.read(source.jobs.get().best_checkpoint)
    assert run.job.log_lines.filter(text__startswith="Starting from the weights").exists()


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_clones_trainer_stays_unsent_however_long_its_weights_take_and_never_sees_part_of_them(
    alice, tracks, settings, monkeypatch
):
    settings.PITLANE_TRAINER_LEASE = 1  # [s] so that the copy below outlasts two leases
    monkeypatch.setattr(leases, "LOST_AFTER", 0)
    source = ready_model(alice)
    during, save = [], FileSystemStorage._save

    def slow_to_a_bucket(storage, name, content):
        if "/checkpoints/cloned" not in name:
            return save(storage, name, content)
        copy = artifacts.path(RLModel(pk=int(name.split("/")[1])), artifacts.CLONED_WEIGHTS)
        if name != copy and storage.exists(copy):
            storage.delete(copy)  # an earlier test's model of that id left one
        stored = save(storage, name, content)
        time.sleep(2.5)
        during.append((storage.exists(copy), leases.lost_queued_claim(waiting=set())))
        return stored

    monkeypatch.setattr(FileSystemStorage, "_save", slow_to_a_bucket)
    clone = clone_of(source)
    assert during == [(False, [])]  # no copy a trainer could read yet, and none sent for
    copy = artifacts.path(clone, artifacts.CLONED_WEIGHTS)
    assert artifacts.read(copy) == artifacts.read(source.jobs.get().best_checkpoint)


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_trainer_that_cannot_make_its_clones_missing_copy_fails_it_in_words(
    alice, tracks, monkeypatch
):
    source = ready_model(alice)
    monkeypatch.setattr(services, "_clone_weights_start", lambda job, weights: True)
    clone = clone_of(source)  # its request died before it copied the weights
    artifacts.default_storage.delete(artifacts.path(clone, artifacts.CLONED_WEIGHTS))
    save = artifacts.save

    def storage_down_for_the_copy(model, relative, data):
        if "cloned" in relative:
            raise OSError("No space left on device")
        return save(model, relative, data)

    monkeypatch.setattr(artifacts, "save", storage_down_for_the_copy)
    assert trainer.run(clone.jobs.get().pk, owner="run", start_rollouts=lambda job, slot: None)
    job = clone.jobs.get()
    assert (job.status, job.failure_reason) == (
        TrainingJob.Status.FAILED,
        "The weights of the model it was cloned from could not be copied (storage failed), so "
        "it did not start training; delete it and clone that model again.",
    )
    assert RLModel.objects.get(pk=clone.pk).status == RLModel.Status.ERROR  # not fresh weights


def test_a_model_cannot_be_deleted_while_a_clone_of_it_waits_to_start_from_its_weights(
    alice, tracks
):
    source = ready_model(alice)
    clone = clone_of(source)
    with pytest.raises(services.ModelBusy) as busy:
        services.model_delete(model=source)
    assert str(busy.value) == (
        "clone, cloned from it, has not started training from its weights yet; delete this "
        "model once clone trains, or stop clone first."
    )
    assert RLModel.objects.get(pk=source.pk).status == RLModel.Status.READY
    services.training_stop(job=clone.jobs.get())
    services.model_delete(model=source)
    assert not RLModel.objects.filter(pk=source.pk).exists()


_ARCHIVES: list[bytes] = []


def archive_of_a_ready_model(owner) -> bytes:
    """A virtual model's download (the same bytes for every ``ready_model``): built once."""
    if not _ARCHIVES:
        _ARCHIVES.append(virtual_archive(ready_model(owner)))
    return _ARCHIVES[0]


@pytest.mark.slow
def test_an_import_stores_its_files_outside_any_transaction(alice, bob, tracks, storage_writes):
    archive = archive_of_a_ready_model(alice)
    storage_writes.clear()
    model = imports.import_model(owner=bob, archive=io.BytesIO(archive)).model
    assert storage_writes and not any(inside for _, inside in storage_writes)
    model.refresh_from_db()
    assert model.status == RLModel.Status.READY
    assert artifacts.read(model.jobs.get().best_checkpoint)


@pytest.mark.slow
def test_an_import_whose_files_cannot_be_stored_leaves_no_model_and_no_files(
    alice, bob, tracks, monkeypatch, own_storage
):
    archive = archive_of_a_ready_model(alice)
    before = stored_objects()
    save = artifacts.save

    def fails_at_the_weights(model, relative, data):
        if relative.startswith("checkpoints/"):
            raise OSError("No space left on device")
        return save(model, relative, data)

    monkeypatch.setattr(artifacts, "save", fails_at_the_weights)
    with pytest.raises(OSError):
        imports.import_model(owner=bob, archive=io.BytesIO(archive))
    assert not RLModel.objects.filter(owner=bob).exists()
    assert stored_objects() == before


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_trainer_saves_each_iterations_checkpoint_outside_its_transaction(
    alice, tracks, storage_writes, monkeypatch
):
    model = services.model_create(owner=alice, settings=training_settings(), validate_reward=False)
    run = trainer.Trainer(leases.lease_acquire(job_id=model.jobs.get().pk, owner="run"), None)
    run._build_learner()
    run.version, run.stopwatch, run.training_message = 0, Stopwatch(), "Training"
    learnt = Update(episodes=1, steps=10, reward=1.0, completion=5.0, best_lap_time=None)
    monkeypatch.setattr(run.learner, "learn", lambda episodes, **how: learnt)
    monkeypatch.setattr(run, "_record_training", lambda number, episodes: None)
    storage_writes.clear()
    assert run._update([])
    checkpoint = artifacts.path(model, artifacts.checkpoint(1))
    assert set(storage_writes) == {(checkpoint, False)}  # (a deletion of an earlier test's first)
    assert TrainingJob.objects.get(pk=run.job.pk).last_checkpoint == checkpoint


@pytest.mark.slow
def test_an_import_whose_undo_cannot_delete_its_row_still_says_why_it_failed(
    alice, bob, tracks, monkeypatch
):
    archive = archive_of_a_ready_model(alice)

    def storage_down(model, relative, data):
        raise OSError("No space left on device")

    def database_locked(model, *args, **kwargs):
        raise OperationalError("database is locked")

    monkeypatch.setattr(artifacts, "save", storage_down)
    monkeypatch.setattr(RLModel, "delete", database_locked)
    with pytest.raises(OSError, match="No space left on device"):
        imports.import_model(owner=bob, archive=io.BytesIO(archive))
    assert RLModel.objects.get(owner=bob).status == RLModel.Status.IMPORTING  # for the sweep


def importing(owner, name: str) -> RLModel:
    """A model as an import inserts it, before it stores its files."""
    checked = configuration.check(training_settings(name=name), owner=owner, validate_reward=False)
    return services.model_insert(owner=owner, settings=checked, status=RLModel.Status.IMPORTING)


def test_an_import_that_died_storing_its_files_is_removed_by_the_workers_heartbeat(bob, tracks):
    died = importing(bob, "died-importing")
    half = artifacts.save(died, "checkpoints/imported-best.safetensors", b"half of the weights")
    long_ago = timezone.now() - timedelta(seconds=imports.ABANDONED_AFTER + 1)
    RLModel.objects.filter(pk=died.pk).update(created_at=long_ago)
    still_storing = importing(bob, "still-importing")

    assert recovery.resume_lapsed()[-1:] == [
        f"import of model {died.pk} stopped as it stored its files; the model was removed"
    ]
    assert list(RLModel.objects.filter(owner=bob)) == [still_storing]  # its name, quota free
    assert not default_storage.exists(half)
