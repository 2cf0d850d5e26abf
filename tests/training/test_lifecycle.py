"""A model's status moves only as training.lifecycle lists, one conditional write at a time."""

import pytest

from tests.training.factories import ready_model
from training import lifecycle
from training.models import RLModel

pytestmark = pytest.mark.django_db

Status = RLModel.Status


def test_every_status_says_where_it_may_go():
    assert set(lifecycle.MOVES) == set(Status.values)
    assert all(targets <= set(Status.values) for targets in lifecycle.MOVES.values())
    reachable = set().union(*lifecycle.MOVES.values()) | lifecycle.BORN
    assert reachable == set(Status.values) - {Status.IMPORTING}  # no import waits half-done now


def test_a_stop_that_lands_while_the_trainer_starts_wins(alice, tracks):
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(status=Status.STOPPING)
    assert not lifecycle.move(model.pk, Status.TRAINING)
    assert lifecycle.move(model.pk, Status.READY)
    model.refresh_from_db()
    assert model.status == Status.READY


def test_a_model_is_deleted_only_from_ready_or_error_and_only_once(alice, tracks):
    model = ready_model(alice)
    deletable = frozenset(RLModel.DELETABLE)
    assert lifecycle.move(model, Status.DELETING, only_from=deletable)
    assert model.status == Status.DELETING
    assert not lifecycle.move(model, Status.DELETING, only_from=deletable)  # a second delete
    assert not lifecycle.move(model, Status.EVALUATING)
    assert lifecycle.move(model, Status.READY)  # the delete failed: the model is given back


def test_an_evaluation_that_ends_late_leaves_a_model_it_no_longer_drives_alone(alice, tracks):
    model = ready_model(alice)
    driving = frozenset({Status.EVALUATING, Status.SUBMITTING})
    assert lifecycle.move(model, Status.SUBMITTING, only_from=frozenset({Status.READY}))
    assert not lifecycle.move(model, Status.EVALUATING, only_from=frozenset({Status.READY}))
    assert lifecycle.move(model, Status.READY, only_from=driving)
    RLModel.objects.filter(pk=model.pk).update(status=Status.DELETING)
    assert not lifecycle.move(model.pk, Status.READY, only_from=driving)
    model.refresh_from_db()
    assert model.status == Status.DELETING
