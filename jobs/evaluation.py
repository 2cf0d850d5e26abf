"""An evaluation: the loop of the ``training.evaluate`` task (and of ``manage.py evaluate``).

The model's policy, loaded from its checkpoint's weights (safetensors, into our own network),
drives the evaluation's track deterministically, trial after trial, under its rules: off-track
and crash penalties, resets, continuous laps or one lap per trial. No racer code runs. Every
simulated 1/15 s becomes a frame of the recorded video (VP8 in WebM: Chromium and Firefox both
play it); the frames someone watches live go to the ``evaluation_<id>`` group, and while someone
watches, the simulation keeps to real time so that they see the race at its speed (an operator
may speed it up: PITLANE_WATCHED_SPEEDUP).

Model against model: an evaluation may be one car of a race of several (``grid_leader``), each
car another model's evaluation with its own trials, trace, video and live frames. The run of the
race's first car drives them all together (``Race``), one car alone being a race of one.

Long because an evaluation's run is one piece: its lease, its drive with the video encoder, the
live frames, the racer's stop, the trials it records and the files it saves.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import queue
import secrets
import socket
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import gymnasium
import numpy as np
import torch
from django.conf import settings
from django.core.files import File
from django.core.files.storage import default_storage
from django.db import DatabaseError, transaction
from django.utils import timezone

import simulator
from common.every import Every
from common.redis_client import redis_client
from common.transactions import outside_transaction
from notifications import services as notifications
from rl import episode
from rl.policies import Policy
from simulator.config import CONTROL_HZ
from simulator.spectator import FRAME_INTERVAL, SIZE, jpeg, view_image
from simulator.trace import SimTraceRow, to_csv
from training import artifacts, leases, lifecycle, selectors, signals, streams
from training.models import EvaluationJob, EvaluationTrial, RLModel

logger = logging.getLogger(__name__)

RUNNABLE = (
    EvaluationJob.Status.QUEUED,
    EvaluationJob.Status.INITIALIZING,
    EvaluationJob.Status.IN_PROGRESS,
    EvaluationJob.Status.STOPPING,
)
VIDEO_CODEC = "VP80"
INTERNAL_ERROR = (
    "The evaluation stopped on an internal error; the model is unchanged. "
    "Try again, and tell the league staff if it happens again."
)
LEASE_RENEWAL = 3.0  # [s] between renewals of a run's lease while it drives


class EvaluationFailed(Exception):
    """The evaluation cannot run; the message is for the racer."""


class _StopAsked(Exception):
    """The racer asked to stop the evaluation (``services.evaluation_stop``)."""


class _VideoWriter:
    """The recorded video, encoded on a thread of its own. VP8 at 640x480 takes 6-11 ms a frame,
    as long as the simulation and the policy together, and OpenCV lets go of the GIL while it
    encodes, so the car drives on while the frames before are written. A few seconds of frames
    may wait; past that, ``write`` waits for the encoder."""

    WAITING = 45  # [frames]

    def __init__(self, path: Path) -> None:
        codec = cv2.VideoWriter_fourcc(*VIDEO_CODEC)
        self._writer = cv2.VideoWriter(str(path), codec, CONTROL_HZ, SIZE)  # a frame a step
        if not self._writer.isOpened():
            raise EvaluationFailed("This worker cannot record video (no VP8 encoder).")
        self._frames: queue.Queue = queue.Queue(maxsize=self.WAITING)
        self._failure: BaseException | None = None
        self._thread = threading.Thread(target=self._encode, name="evaluation-video", daemon=True)
        self._thread.start()

    def write(self, frame: np.ndarray) -> None:
        self._frames.put(frame)

    def close(self) -> None:
        """Write what is waiting and finish the file."""
        self._frames.put(None)
        self._thread.join()
        self._writer.release()
        if self._failure is not None:
            raise EvaluationFailed("The video could not be recorded.") from self._failure

    def _encode(self) -> None:
        try:
            while (frame := self._frames.get()) is not None:
                self._writer.write(frame)
        except Exception as error:  # close() says so
            self._failure = error
            while self._frames.get() is not None:
                pass  # the drive never waits on an encoder that has stopped


@contextlib.contextmanager
def _one_torch_thread() -> Iterator[None]:
    """The policy drives on one core while the video encodes on another. With PyTorch's usual
    threads, every layer waits for the thread that shares the encoder's core: a step of the
    policy took ten times as long (measured with cProfile on this 2-core machine)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def run(evaluation_id: int) -> EvaluationJob | None:
    """Run evaluation ``evaluation_id`` if it is waiting; None when it has ended or vanished, or
    another run drives it.

    An evaluation may be one car of a race of several (model against model): the run of the
    race's first car (its ``grid_leader``) drives them all together, each car on simapp's grid
    with its own model, trials, trace, video and live frames; a run asked for another car
    drives its race's first.

    The run holds a lease on the evaluations while it drives (renewed every few seconds), as a
    trainer holds its job's. One that is under way with a lapsed lease lost its worker (the
    heartbeat's ``leases.lapsed_evaluations`` sent for this run, or Celery redelivered the task,
    which it acknowledges late): it starts over, so the racer gets a whole evaluation, not half
    of one. One whose lease is alive is a duplicate delivery, and is left to its run.

    The racer may stop an evaluation that drives alone (``services.evaluation_stop``): the run
    looks twice a second, and ends it CANCELED with the trials it finished, their video and
    trace (one whose run died as it was being stopped ends with the trials recorded)."""
    owner = f"{socket.gethostname()}:{os.getpid()}:{secrets.token_hex(4)}"
    with transaction.atomic():
        evaluation = EvaluationJob.objects.select_for_update().filter(pk=evaluation_id).first()
        leader = evaluation.grid_leader_id if evaluation is not None else None
        race = [] if leader is not None else _claim(evaluation, owner)
    if leader is not None:
        logger.info("Evaluation %s drives in evaluation %s's race", evaluation_id, leader)
        return run(leader)
    if not race:
        return None
    race = [EvaluationJob.objects.select_related("model", "track").get(pk=car.pk) for car in race]
    for car in race:
        _announce(car)
    cars = [EvaluationCar(car) for car in race]
    try:
        with _one_torch_thread():
            Race(cars).run()
    except leases.LeaseLost:
        logger.warning("Evaluation %s was taken over by another run; this one stops", evaluation_id)
        return None
    except EvaluationFailed as failure:
        for car in cars:
            _finish(car.evaluation, EvaluationJob.Status.FAILED, str(failure))
    except Exception:
        logger.exception("Evaluation %s failed", evaluation_id)
        for car in cars:
            _finish(car.evaluation, EvaluationJob.Status.FAILED, INTERNAL_ERROR)
    else:
        for car in cars:
            if car.failure:
                _finish(car.evaluation, EvaluationJob.Status.FAILED, car.failure)
            elif car.stopped:
                _finish(car.evaluation, EvaluationJob.Status.CANCELED, leases.EVALUATION_STOPPED)
            else:
                _finish(car.evaluation, EvaluationJob.Status.COMPLETED)
    return race[0]


def _claim(evaluation: EvaluationJob | None, owner: str) -> list[EvaluationJob]:
    """Within the transaction that locked ``evaluation`` (the first car of its race, or alone):
    its race's cars that are waiting, in grid order, each INITIALIZING under ``owner``'s lease;
    none when it has ended, another run drives it, or the racer stopped it as its run died."""
    if evaluation is None or evaluation.status not in RUNNABLE:
        logger.info("Evaluation %s is not waiting; nothing to do", getattr(evaluation, "pk", None))
        return []
    now = timezone.now()
    if evaluation.status != EvaluationJob.Status.QUEUED:
        held = evaluation.lease_owner not in ("", leases.RESUMING)
        if held and evaluation.lease_expires and evaluation.lease_expires > now:
            logger.info("Evaluation %s is being driven by another run", evaluation.pk)
            return []
        if evaluation.status == EvaluationJob.Status.STOPPING:
            _end_stopped(evaluation)
            return []
        logger.warning("Evaluation %s was interrupted; starting it over", evaluation.pk)
    others = evaluation.grid.select_for_update().filter(status__in=RUNNABLE)
    race = [evaluation, *others.order_by("grid_position", "pk")]
    for car in race:
        if car.status != EvaluationJob.Status.QUEUED:
            car.trial_rows.all().delete()
        lifecycle.EVALUATION.move(
            car,
            EvaluationJob.Status.INITIALIZING,
            started_at=now,
            message="Loading the model",
            lease_owner=owner,
            lease_expires=now + leases.lease(),
        )
    return race


class Race:
    """An evaluation's cars driven together: one car, or a race's (model against model), each an
    ``EvaluationCar`` driving its own episode of one fleet (``rl.episode.Fleet`` with
    ``race=True``: every car of the race on its place on the grid, knowing where the others
    stand before it steps)."""

    def __init__(self, cars: list[EvaluationCar]) -> None:
        self.cars = cars  # in grid order
        self.racing: list[EvaluationCar] = []  # those whose weights could be read

    def run(self) -> None:
        """Drive the cars from their weights to their saved files: a car whose weights cannot be
        read is left out (it fails with the reason); the others drive together."""
        for car in self.cars:
            try:
                car.load()
            except EvaluationFailed as failure:
                car.failure = str(failure)
        self.racing = [car for car in self.cars if not car.failure]
        if not self.racing:
            return
        race, prepared = [car.evaluation for car in self.racing], []
        try:
            for car in self.racing:
                car.prepare(race)
                prepared.append(car)
        except EvaluationFailed:  # the race fails with it: the simulations built are let go
            for car in prepared:
                car.env.close()
            raise
        if not all([car.begin() for car in self.racing]):  # the racer stopped it as it loaded
            for car in self.racing:
                car.stopped = True
                car.env.close()
            return
        with contextlib.ExitStack() as recordings:
            for car in self.racing:
                recordings.enter_context(car.recording())
            with contextlib.suppress(_StopAsked):  # the car that asked is ``stopped``
                self._drive()

    def _drive(self) -> None:
        """The trials: each car's an episode of the fleet (continuous laps are one episode), each
        car with its own policy, every car reset on its place on the grid. A car whose trial is
        over is parked off the field while the others drive on, as simapp parks it
        (DONE_CONDITION "all", evaluation_worker.py:343, 01f5f01), so that every racer drives its
        own laps. Each step, every car's trace row, video frame and live frames, and each lap
        recorded as it ends (``EvaluationCar.stepped``); then one wait, while someone watches or
        the race is live, so that the step takes real time (or PITLANE_WATCHED_SPEEDUP times
        less)."""
        cars = self.racing
        rules = cars[0].evaluation  # the race's trials and laps, its first car's
        fleet = episode.Fleet([car.env for car in cars], cars[0].policy, race=True)
        for car, driving in zip(cars, fleet.cars, strict=True):
            car.driving, driving.policy = driving, car.policy
        pace = cars[0].env.unwrapped.dt / settings.PITLANE_WATCHED_SPEEDUP  # [s] a step, real
        last_step = 0.0
        paced: list[bool] = []  # this step's cars: whether each should take real time

        def stepped(driving: episode.Car, *seen) -> None:
            paced.append(cars[driving.index].stepped(*seen))

        for number in range(1 if rules.continuous_laps else rules.trials):
            for car in cars:
                seed = car.trial_begins(number)
                car.started(*fleet.start(car.driving, "evaluate", record=False, seed=seed))
            while fleet.driving():
                paced.clear()
                fleet.step(stepped)
                if any(paced):
                    time.sleep(max(0.0, pace - (time.monotonic() - last_step)))
                last_step = time.monotonic()
            for car in cars:
                car.trial_ends(car.driving.driven)


@dataclass
class LapCounts:
    """The environment's counts when a trial began, to tell what happened during it."""

    off_tracks: int = 0
    crashes: int = 0
    resets: int = 0
    reversed: int = 0
    immobilized: int = 0
    started: float = 0.0  # [s] simulated time


class EvaluationCar:
    """One car of an evaluation's run: its model's policy and environment, the trials it
    records, its trace, video, live frames and lease, and its files once driven."""

    def __init__(self, evaluation: EvaluationJob) -> None:
        self.evaluation = evaluation
        self.model: RLModel = evaluation.model
        self.trace: list[SimTraceRow] = []
        self.metrics: list[dict] = []
        self.results: list[EvaluationTrial] = []
        self.failure = ""  # why it cannot drive (its weights), when it cannot
        self.stopped = False  # the racer stopped it: it ends with the trials it finished
        self._seed: int | None = None  # the seed of the episode driving
        self.driving: episode.Car | None = None  # its car in the race's fleet, once it drives
        # the lease renewed, and the racer's stop looked for, every so often while it drives
        self.renewals = Every(LEASE_RENEWAL, at_once=False)
        self.stop_looks = Every(leases.EVALUATION_STOP_LOOK, at_once=False)
        self._last_live = 0.0  # when it last offered live frames
        self._weights = b""
        self.line: tuple[float, float] | None = None  # the racing line's laps, once loaded

    def load(self) -> None:
        """Read the model's weights (``EvaluationFailed`` says why it cannot)."""
        checkpoint = selectors.model_checkpoint(model=self.model, which=self.evaluation.checkpoint)
        if checkpoint is None:
            raise EvaluationFailed(f"The model {self.model.name} has no trained weights.")
        self._weights = artifacts.read(checkpoint)
        self.line = selectors.evaluation_line(
            evaluation=self.evaluation
        )  # what laps are set against
        _update(
            self.evaluation,
            checkpoint_name=checkpoint,
            checkpoint_iteration=artifacts.checkpoint_iteration(checkpoint),
        )

    def prepare(self, race: list[EvaluationJob]) -> None:
        """Its environment, in ``race`` (this car alone, or the race's cars in grid order), and
        its policy with the weights read."""
        self.env = gymnasium.make(simulator.ENV_ID, **self.evaluation.environment_settings(race))
        self.policy = Policy.build(
            self.model.algorithm,
            self.model.architecture,
            self.env.observation_space,
            self.env.action_space,
            loading=True,
        )
        try:
            self.policy.load_checkpoint(self._weights)
        except (ValueError, OSError) as error:
            self.env.close()
            raise EvaluationFailed(
                f"The weights of {self.model.name} could not be loaded: {error}"
            ) from None

    def begin(self) -> bool:
        """IN_PROGRESS, and said so; False when the racer stopped it as it loaded."""
        moved = lifecycle.EVALUATION.move(
            self.evaluation, EvaluationJob.Status.IN_PROGRESS, message="Racing"
        )
        if moved:
            _announce(self.evaluation)
        return moved

    @contextlib.contextmanager
    def recording(self) -> Iterator[None]:
        """While the car drives: its video's encoder and its live frames' publisher; then its
        trace, metrics and video saved (unless the drive failed)."""
        with tempfile.TemporaryDirectory(prefix="pitlane-evaluation-") as directory:
            video_path = Path(directory) / artifacts.EVALUATION_VIDEO
            self._writer = _VideoWriter(video_path)
            group = streams.evaluation_group(self.evaluation.pk)
            try:
                with streams.FramePublisher(redis_client(timeout=5.0), group) as self._publisher:
                    yield
            finally:
                self._writer.close()
                self.env.close()
            self._renew()  # the uploads below may take a while: hold the lease through them
            self._save(video_path)

    # Driving

    def trial_begins(self, number: int) -> int:
        """Trial ``number`` (0 on) begins: the seed of its episode."""
        self._counts, self._laps_done = LapCounts(), 0
        # Each trial's own seed draws its noise; one from before seeds drives without.
        self._seed = self.evaluation.trial_seed(number)
        return number if self._seed is None else self._seed

    def trial_ends(self, driven: episode.Driven) -> None:
        status = "time_up" if driven.truncated else driven.info["status"]
        if status != "lap_complete" and len(self.results) < self.evaluation.trials:
            # Out of time, or out of resets (``max_resets``): the part of a lap it drove.
            seconds = self.env.unwrapped.sim_time - self._counts.started
            self._record(self.env.unwrapped, driven.info, self._counts, seconds, status=status)

    def started(self, observation: dict, info: dict) -> None:
        # Trace rows are numbered by trials done, so each lap of continuous laps is its own
        # episode, as DeepRacer's evaluation numbers them (simapp rollout_agent_ctrl.py:819);
        # the seeded reset restarts the env's clock, so tstamp runs on from the last row.
        self._clock = self.trace[-1].tstamp if self.trace else 0.0
        self.trace.append(self._row(info))  # the prepare row

    def _row(self, info: dict) -> SimTraceRow:
        trace = info["trace"]
        return trace._replace(
            episode=len(self.results), tstamp=self._clock + trace.tstamp, wall_clock=time.time()
        )

    def stepped(self, observation: dict, info: dict, done: bool) -> bool:
        """Record a step; whether it should take real time (watched, or a live race's)."""
        self._renew()
        self._look_for_stop()
        unwrapped = self.env.unwrapped
        self.trace.append(self._row(info))
        frame = unwrapped.spectator.render(unwrapped)
        self._writer.write(frame)
        watched = self._publisher.watched(0)
        now = time.monotonic()
        if watched and now - self._last_live >= FRAME_INTERVAL:
            self._last_live = now
            self._show(self._publisher, watched, unwrapped, frame, observation)
        # a lap that ended is announced with its last frame, before the step's wait: a live
        # race's lap timer stops on the lap's time, not a step's wait after it
        while len(info["lap_times"]) > self._laps_done:
            self._laps_done += 1
            lap_time = info["lap_times"][self._laps_done - 1]
            self._counts = self._record(
                unwrapped, info, self._counts, lap_time, status="lap_complete"
            )
        return bool(watched) or self.evaluation.real_time

    def _look_for_stop(self) -> None:
        """``_StopAsked``, the car ``stopped``, once the racer has asked to stop (looked for
        twice a second)."""
        if not self.stop_looks.due():
            return
        stopping = EvaluationJob.Status.STOPPING
        try:
            asked = EvaluationJob.objects.filter(pk=self.evaluation.pk, status=stopping).exists()
        except DatabaseError:
            return  # looked for again in half a second
        if asked:
            self.stopped = True  # the trials it finished, and what was driven, are saved
            raise _StopAsked

    def _renew(self) -> None:
        """Hold the lease while driving; ``leases.LeaseLost`` once another run has it. A database
        that does not answer is tried again at the next renewal, within the lease."""
        if not self.renewals.due():
            return
        evaluation = self.evaluation
        try:
            held = EvaluationJob.objects.filter(
                pk=evaluation.pk, lease_owner=evaluation.lease_owner
            ).update(lease_expires=timezone.now() + leases.lease())
        except DatabaseError as error:
            logger.warning("Evaluation %s could not renew its lease: %s", evaluation.pk, error)
            return
        if not held:
            raise leases.LeaseLost(f"evaluation {evaluation.pk}")

    def _show(
        self, publisher: streams.FramePublisher, views, unwrapped, frame, observation
    ) -> None:
        """Offer this step's ``views`` (the spectator's is the video's ``frame``) to the live
        viewers."""
        for view in views:
            image = frame if view == "spectator" else view_image(unwrapped, view, observation)
            publisher.offer(
                streams.frame_event(
                    0,
                    view,
                    jpeg(image),
                    step=unwrapped.steps,
                    status=unwrapped.status,
                    progress=unwrapped.progress,
                    episode=len(self.results) + 1,
                    lap_ms=round((unwrapped.sim_time - self._counts.started) * 1000),
                )
            )

    def _record(
        self, env, info: dict, before: LapCounts, seconds: float, *, status: str
    ) -> LapCounts:
        """The trial that just ended with ``status``: a lap, or the part of one driven before
        time or resets ran out; the counts the next trial starts from."""
        evaluation = self.evaluation
        now = env.counts
        off_tracks = now["off_tracks"] - before.off_tracks
        crashes = now["crashes"] - before.crashes
        trial = EvaluationTrial.objects.create(
            evaluation=evaluation,
            number=len(self.results) + 1,
            time_ms=round(seconds * 1000),
            progress=100.0 if status == "lap_complete" else round(info["progress"], 2),
            status=status,
            off_tracks=off_tracks,
            crashes=crashes,
            resets=now["resets"] - before.resets,
            seed=self._seed,
            penalty_ms=round(
                1000
                * (off_tracks * evaluation.off_track_penalty + crashes * evaluation.crash_penalty)
            ),
        )
        self.results.append(trial)
        wall = time.time()
        self.metrics.append(
            {
                "completion_percentage": round(trial.progress),
                "metric_time": int(wall * 1000),
                "start_time": int((wall - seconds) * 1000),
                "elapsed_time_in_milliseconds": trial.time_ms,
                "episode_status": artifacts.status_label(trial.status),
                "crash_count": crashes,
                "immobilized_count": now["immobilized"] - before.immobilized,
                "off_track_count": off_tracks,
                "reversed_count": now["reversed"] - before.reversed,
                "reset_count": trial.resets,
                "trial": trial.number,
            }
        )
        row = selectors.trial_row(trial=trial, line=self.line)
        streams.announce(streams.evaluation_group(evaluation.pk), row)
        return LapCounts(
            now["off_tracks"],
            now["crashes"],
            now["resets"],
            now["reversed"],
            now["immobilized"],
            env.sim_time,
        )

    # Files

    def _save(self, video_path: Path) -> None:
        prefix = artifacts.evaluation_prefix(self.evaluation)
        trace = to_csv(self.trace)
        artifacts.save(self.model, prefix + artifacts.EVALUATION_TRACE, trace)
        signals.trace_recorded.send(EvaluationJob, document=trace, evaluation=self.evaluation)
        self._renew()
        artifacts.save(
            self.model, prefix + artifacts.EVALUATION_METRICS, json.dumps({"metrics": self.metrics})
        )
        name = artifacts.path(self.model, prefix + artifacts.EVALUATION_VIDEO)
        if default_storage.exists(name):
            default_storage.delete(name)
        outside_transaction("An evaluation's video written to storage")
        with video_path.open("rb") as handle:
            saved = default_storage.save(name, File(handle))
        _update(self.evaluation, video=saved)


def _update(evaluation: EvaluationJob, **fields) -> None:
    """Write ``fields`` (not the status: ``lifecycle.EVALUATION`` moves that); mirror them."""
    EvaluationJob.objects.filter(pk=evaluation.pk).update(**fields)
    for name, value in fields.items():
        setattr(evaluation, name, value)


def _finish(evaluation: EvaluationJob, status: str, reason: str = "") -> None:
    """End the evaluation, free its model and tell the racer; nothing if another run took the
    evaluation over meanwhile (its lease lapsed): that run ends it."""
    held = EvaluationJob.objects.filter(lease_owner=evaluation.lease_owner)  # not taken over
    if not lifecycle.EVALUATION.move(
        evaluation,
        status,
        within=held,
        failure_reason=reason,
        message="",
        finished_at=timezone.now(),
        lease_owner="",
        lease_expires=None,
    ):
        logger.warning("Evaluation %s was taken over by another run; it ends it", evaluation.pk)
        return
    # a rival car's model (another racer's, raced against theirs) was neither held nor is told
    if not evaluation.rival:
        _model_free(evaluation)
    _announce(evaluation)  # once the model is free: the page that hears it may race it again
    if not evaluation.rival and status != EvaluationJob.Status.CANCELED:  # stopped: they know
        notifications.evaluation_ended(evaluation=evaluation)


def _end_stopped(evaluation: EvaluationJob) -> None:
    """Within the transaction that locks it: end an evaluation whose run died as the racer
    stopped it, with the trials it recorded (and its video and trace where it saved them before
    it died); its model is freed and the racer told once that transaction commits."""
    reason = leases.EVALUATION_STOPPED if evaluation.video else leases.EVALUATION_STOPPED_UNSAVED
    lifecycle.EVALUATION.move(
        evaluation,
        EvaluationJob.Status.CANCELED,
        finished_at=timezone.now(),
        message="",
        failure_reason=reason,
        lease_owner="",
        lease_expires=None,
    )

    def after_commit() -> None:
        _model_free(evaluation)
        _announce(evaluation)

    transaction.on_commit(after_commit)


def _model_free(evaluation: EvaluationJob) -> None:
    driving = frozenset({RLModel.Status.EVALUATING, RLModel.Status.SUBMITTING})
    lifecycle.MODEL.move(evaluation.model_id, RLModel.Status.READY, only_from=driving)


def _announce(evaluation: EvaluationJob) -> None:
    streams.announce(
        streams.evaluation_group(evaluation.pk), selectors.evaluation_status(evaluation=evaluation)
    )
