"""The statuses of a model, a training job and an evaluation, and the moves between their values
(``common.lifecycle``): after a row is created (in one of its ``born`` statuses), every write of
its status is a ``move`` here, which makes only the moves its table lists. (A race entry's
table is racing's, ``racing.services.SUBMISSION``, made the same way.)

A move is one conditional UPDATE (the status changes only from a value it may change from), so two
writers racing cannot take a row where neither meant: a racer's stop that lands while the trainer
starts leaves the model STOPPING, not TRAINING; an evaluation that ends after the model was deleted
writes nothing; a trainer that prepares a job the racer has just stopped finds it STOPPING.
"""

from __future__ import annotations

from common.lifecycle import Lifecycle
from training.models import EvaluationJob, RLModel, TrackLine, TrainingJob

_M = RLModel.Status
MODEL = Lifecycle(
    RLModel,
    {
        # The trainer takes it up; the racer stops it before or while it starts; the trainer
        # ends it.
        _M.QUEUED: frozenset({_M.TRAINING, _M.STOPPING, _M.READY, _M.ERROR}),
        # The racer stops it; the trainer ends it (READY with a checkpoint, ERROR without).
        _M.TRAINING: frozenset({_M.STOPPING, _M.READY, _M.ERROR}),
        _M.STOPPING: frozenset({_M.READY, _M.ERROR}),
        # An evaluation or a race entry drives it; the racer deletes it.
        _M.READY: frozenset({_M.EVALUATING, _M.SUBMITTING, _M.DELETING}),
        _M.ERROR: frozenset({_M.DELETING}),
        _M.EVALUATING: frozenset({_M.READY}),
        _M.SUBMITTING: frozenset({_M.READY}),
        # A delete whose storage failed part-way gives the model back as it was.
        _M.DELETING: frozenset({_M.READY, _M.ERROR}),
        _M.IMPORTING: frozenset({_M.READY, _M.ERROR}),
    },
    # A new model queued for training; an import with its weights, IMPORTING while they are
    # stored (outside the transaction that inserted its row), then READY.
    born=frozenset({_M.QUEUED, _M.IMPORTING}),
)

_J = TrainingJob.Status
TRAINING_JOB = Lifecycle(
    TrainingJob,
    {
        # A trainer run takes it up; the racer stops it before any run did (canceled) or after
        # one took its lease (stopping); a run that fails before it starts ends it, stopping.
        _J.QUEUED: frozenset({_J.INITIALIZING, _J.CANCELED, _J.STOPPING}),
        # The run starts training; the racer stops it; a run that took over prepares it again.
        _J.INITIALIZING: frozenset({_J.IN_PROGRESS, _J.STOPPING}),
        _J.IN_PROGRESS: frozenset({_J.STOPPING, _J.INITIALIZING}),
        # The run saves the model from its last iteration, then ends the job.
        _J.STOPPING: frozenset({_J.COMPLETED, _J.FAILED}),
        _J.COMPLETED: frozenset(),
        _J.FAILED: frozenset(),
        _J.CANCELED: frozenset(),
    },
    # A job created with its model; a model imported with its weights comes with a finished one.
    born=frozenset({_J.QUEUED, _J.COMPLETED}),
)

_E = EvaluationJob.Status
EVALUATION = Lifecycle(
    EvaluationJob,
    {
        # A run loads the model and drives it. A run redelivered after its worker died starts an
        # interrupted evaluation over (INITIALIZING again), so the racer gets a whole one. The
        # racer's "Stop evaluation" cancels one still waiting, and asks a running one to stop
        # (STOPPING): its run ends it, CANCELED with the trials it finished, or COMPLETED if
        # the last trial ended as the stop came.
        _E.QUEUED: frozenset({_E.INITIALIZING, _E.CANCELED}),
        _E.INITIALIZING: frozenset({_E.IN_PROGRESS, _E.FAILED, _E.STOPPING}),
        _E.IN_PROGRESS: frozenset({_E.INITIALIZING, _E.COMPLETED, _E.FAILED, _E.STOPPING}),
        _E.STOPPING: frozenset({_E.CANCELED, _E.COMPLETED, _E.FAILED}),
        _E.COMPLETED: frozenset(),
        _E.FAILED: frozenset(),
        _E.CANCELED: frozenset(),
    },
    born=frozenset({_E.QUEUED}),
)

_L = TrackLine.Status
TRACK_LINE = Lifecycle(
    TrackLine,
    {
        # A worker computes it, or finds the route gives no line; a look that finds it lost
        # with its worker asks again.
        _L.COMPUTING: frozenset({_L.READY, _L.FAILED}),
        # A changed track, car or method makes it stale: it is computed again.
        _L.READY: frozenset({_L.COMPUTING}),
        _L.FAILED: frozenset({_L.COMPUTING}),
    },
    born=frozenset({_L.COMPUTING}),
)
