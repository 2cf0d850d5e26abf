"""A club evening on one machine: `python -m bench.bench_club_evening` (issue 42).

Starts the whole console as `make run` does (its supervisor, its own Redis, a Celery worker per
queue with the processes make run would choose for this machine, ``console.sizing``, unless
``--trainers`` and ``--simulations`` say; Daphne, SQLite, all in a scratch directory on free
ports), then
plays an evening: ``--racers`` racers (6) each create a model with DeepRacer's defaults (as
bench_training does, through training.services as the create page does) at once, and each
presses Stop after ``--minutes`` (5) of training, then evaluates the model (3 trials, defaults).
Meanwhile, over real HTTP with signed-in sessions and CSRF tokens, as the pages' scripts send them:

- ``--flooders`` racers (2) flood Validate (the create page's endpoint), two requests in flight
  each, one after another; after a refusal (429, 503) they try again half a second later;
- a bystander validates DeepRacer's example every 10 s, and loads the home page every 2 s;
- the first racer keeps re-scoring their job's latest iterations with a heavy reward function
  (the analysis page's re-score endpoint), as many at once as the console lets one racer have.

Validate's rate limit is lifted (``PITLANE_RATE_VALIDATE``) so that the flood lasts the whole
evening; ``--console-rates`` keeps make run's rates (the flooders are then turned away with 429s
within a minute). Printed: each job's wait in the queue, training time, iterations, steps/s and
final status, when its car drove and its first policy update landed (from Train), and the machine's
total steps/s; each evaluation's wait and whether a re-scoring ran while it waited; Validate's
p50/p95 for the flooders and for the bystander; the home page's p50/p95; the re-scorings; and a
PASS or FAIL line per target of the issue: no job fails or starves, the bystander's Validate
answers within 10 s at p95 (a refused try counts as never answered), no evaluation waits behind a
re-scoring; and issue 56's: every car drives within 2 minutes of Train, every first update within
10.
A shorter evening: ``--racers 2 --flooders 1`` (about 15 minutes); with fewer
``--minutes`` a job on a busy machine may be stopped before its first iteration, which counts as
starving. Every process it started is stopped when it ends, fails or is interrupted (Ctrl-C,
SIGTERM).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import requests

from bench.bench_console import percentile
from bench.stack import running_console
from common.formatting import clock
from console.sizing import machine_sizing

TRACK = "rookie-loop"
BYSTANDER_PAUSE = 10.0  # [s] between the bystander's checks, as someone editing their code
HOME_PAUSE = 2.0  # [s] between the bystander's home page loads
REFUSED_PAUSE = 0.5  # [s] a flooder waits after a refusal
FLOOD_IN_FLIGHT = 2  # a flooder's requests at once (checks.RACER_PLACES: more are refused)
RESCORE_POLL = 5.0  # [s] between the re-scorer's looks at their re-scorings
DRIVE_POLL = 2.0  # [s] between the evening's looks at the jobs
REQUEST_TIMEOUT = 120.0  # [s]
VALIDATE_TARGET = 10.0  # [s] the bystander's Validate at p95 (issue 42)
# [s] an evaluation's longest wait in the queue, with a simulation process free for it: taking a
# task up is a matter of seconds; behind a re-scoring it waited minutes (issue 42: 14 min 46 s).
EVALUATION_WAIT_TARGET = 30.0
DRIVES_TARGET = 120.0  # [s] from Train to the racer's car driving (issue 56)
UPDATE_TARGET = 600.0  # [s] from Train to the job's first policy update (issue 56)
LIFTED_VALIDATE_RATE = "100000/10m"
# A racer's heavy reward function, to re-score with: every waypoint's distance, many times over,
# at every step, so that one re-scoring holds its process for minutes.
HEAVY_REWARD = """\
import math


def reward_function(params):
    here = (params["x"], params["y"])
    nearest = min(math.dist(here, point) for _ in range(400) for point in params["waypoints"])
    return 1.0 / (1.0 + nearest)
"""


@dataclass
class Answers:
    """How long each request took [s], by its outcome."""

    answered: list[float] = field(default_factory=list)  # 200
    refused: dict[int, int] = field(default_factory=dict)  # status: count (429, 503; 0: none)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, status: int, seconds: float) -> None:
        with self.lock:
            if status == 200:
                self.answered.append(seconds)
            else:
                self.refused[status] = self.refused.get(status, 0) + 1

    @property
    def tries(self) -> int:
        return len(self.answered) + sum(self.refused.values())

    def p95_counting_refusals(self) -> float:
        """p95 with each refused try as never answered (infinitely slow)."""
        times = self.answered + [math.inf] * sum(self.refused.values())
        return percentile(times, 0.95) if times else math.inf

    def line(self) -> str:
        if not self.tries:
            return "no tries"
        refused = ", ".join(
            f"{status or 'no answer'}: {n}" for status, n in sorted(self.refused.items())
        )
        shown = (
            f"p50 {statistics.median(self.answered):.2f} s, "
            f"p95 {percentile(self.answered, 0.95):.2f} s"
            if self.answered
            else "none answered"
        )
        return f"{len(self.answered)} of {self.tries} answered, {shown}; refused: {refused or '0'}"


class Browser:
    """A racer's browser: a signed-in session on the served console, with its CSRF token."""

    def __init__(self, base: str, owner) -> None:
        from django.conf import settings
        from django.test import Client

        client = Client()
        client.force_login(owner)
        self.base = base
        self.session = requests.Session()
        self.session.cookies.set(
            settings.SESSION_COOKIE_NAME, client.cookies[settings.SESSION_COOKIE_NAME].value
        )
        self.session.get(f"{base}/models/create/", timeout=REQUEST_TIMEOUT).raise_for_status()
        self.token = self.session.cookies[settings.CSRF_COOKIE_NAME]

    def get(self, path: str) -> tuple[int, float]:
        """The page's status (0: no answer) and how long it took."""
        started = time.perf_counter()
        try:
            status = self.session.get(self.base + path, timeout=REQUEST_TIMEOUT).status_code
        except requests.RequestException:
            status = 0
        return status, time.perf_counter() - started

    def post(self, path: str, data: dict) -> tuple[requests.Response, float]:
        started = time.perf_counter()
        response = self.session.post(
            self.base + path,
            data=data,
            headers={"X-CSRFToken": self.token},
            timeout=REQUEST_TIMEOUT,
        )
        return response, time.perf_counter() - started

    def validate(self, source: str) -> tuple[int, float]:
        """Validate's status (0: no answer) and how long it took."""
        started = time.perf_counter()
        try:
            response, _ = self.post(
                "/models/reward-function/validate/", {"source": source, "track": TRACK}
            )
        except requests.RequestException:
            return 0, time.perf_counter() - started
        return response.status_code, time.perf_counter() - started


class Evening:
    """The racers, their models and the figures, while the evening goes on."""

    def __init__(self, base: str, arguments: argparse.Namespace) -> None:
        from bench.bench_training import bench_racer

        self.base, self.arguments = base, arguments
        self.stop = threading.Event()
        self.flood, self.bystander, self.home = Answers(), Answers(), Answers()
        self.rescore_refusals: dict[int, int] = {}
        self.racers = [bench_racer(f"racer-{n}") for n in range(1, arguments.racers + 1)]
        self.flooders = [bench_racer(f"flooder-{n}") for n in range(1, arguments.flooders + 1)]
        self.bystander_racer = bench_racer("bystander")
        self.models: list = []
        self.evaluations: dict[int, object] = {}  # model pk: its evaluation
        self.refused_evaluations: dict[int, str] = {}  # model pk: why it was not evaluated
        self.threads: list[threading.Thread] = []
        self.began = time.monotonic()
        self.seen: dict[str, str] = {}  # the last status said of each job and evaluation

    # The racers' parts, each in a thread of its own

    def _loop(self, work: Callable[[], float]) -> None:
        """``work`` until the evening ends, waiting after each time the seconds it says."""
        from django.db import connection

        try:
            while not self.stop.is_set():
                self.stop.wait(work())
        finally:
            connection.close()

    def _start(self, target, *args) -> None:
        thread = threading.Thread(target=target, args=args, daemon=True)
        thread.start()
        self.threads.append(thread)

    def _flood(self, browser: Browser) -> None:
        from training.rewards import EXAMPLES

        def once() -> float:
            status, seconds = browser.validate(EXAMPLES[0].source)
            self.flood.add(status, seconds)
            return 0.0 if status == 200 else REFUSED_PAUSE

        self._loop(once)

    def _bystand(self, browser: Browser) -> None:
        from training.rewards import EXAMPLES

        def once() -> float:
            self.bystander.add(*browser.validate(EXAMPLES[0].source))
            return BYSTANDER_PAUSE

        self._loop(once)

    def _visit_home(self, browser: Browser) -> None:
        def once() -> float:
            self.home.add(*browser.get("/"))
            return HOME_PAUSE

        self._loop(once)

    def _rescore(self, browser: Browser, model) -> None:
        from analysis.models import Rescoring
        from analysis.services import MAX_RESCORINGS_AT_ONCE

        def once() -> float:
            active = Rescoring.objects.filter(owner=model.owner, status__in=("QUEUED", "RUNNING"))
            if (
                active.count() >= MAX_RESCORINGS_AT_ONCE
                or not model.jobs.filter(iterations__gt=0).exists()
            ):
                return RESCORE_POLL
            try:
                response, _ = browser.post(
                    f"/models/{model.pk}/analysis/rescore/",
                    {"saved": "", "reward_function": HEAVY_REWARD, "first": "", "last": ""},
                )
            except requests.RequestException:
                self.rescore_refusals[0] = self.rescore_refusals.get(0, 0) + 1
                return RESCORE_POLL
            if response.status_code == 202:
                asked = response.json()
                self._say(
                    f"{model.owner.username} asked for a re-scoring of iterations "
                    f"{asked['first']}-{asked['last']} ({asked['total_steps']:,} steps)"
                )
                return 0.0
            self.rescore_refusals[response.status_code] = (
                self.rescore_refusals.get(response.status_code, 0) + 1
            )
            return max(float(response.headers.get("Retry-After", 0)), RESCORE_POLL)

        self._loop(once)

    # The evening

    def run(self) -> bool:
        """Play the evening until every job and evaluation has ended; False when it had to be
        given up (``--patience``), with jobs still waiting or training."""
        from bench.bench_training import default_model

        deadline = time.monotonic() + self.arguments.patience * 60
        try:
            for racer in self.racers:
                self.models.append(default_model(racer, f"evening-{racer.username}"))
            for flooder in self.flooders:
                for _ in range(FLOOD_IN_FLIGHT):
                    self._start(self._flood, Browser(self.base, flooder))
            self._start(self._bystand, Browser(self.base, self.bystander_racer))
            self._start(self._visit_home, Browser(self.base, self.bystander_racer))
            self._start(self._rescore, Browser(self.base, self.racers[0]), self.models[0])
            while not self._over():
                if time.monotonic() > deadline:
                    return False
                self._drive()
                time.sleep(DRIVE_POLL)
            return True
        finally:
            self.stop.set()
            for thread in self.threads:
                thread.join(5)

    def _drive(self) -> None:
        """What each racer does now: Stop a job that trained its minutes; evaluate a model whose
        training has ended."""
        from bench.bench_training import job_of
        from training.selectors import training_clock
        from training.services import EvaluationRefused, evaluation_start, training_stop

        for model in self.models:
            job, name = job_of(model), model.owner.username
            self._progress(f"{name}'s training", job.status, f"{job.iterations} iterations")
            # The racer reads the clock on the model page (the time billed) and presses Stop.
            billed = training_clock(job=job)
            if billed.running and billed.seconds >= self.arguments.minutes * 60:
                training_stop(job=job)
            model.refresh_from_db()
            if model.pk in self.evaluations:
                evaluation = self.evaluations[model.pk]
                evaluation.refresh_from_db()
                self._progress(f"{name}'s evaluation", evaluation.status)
            elif (
                job.status == "COMPLETED"
                and model.status == "READY"
                and model.pk not in self.refused_evaluations
            ):
                try:
                    self.evaluations[model.pk] = evaluation_start(model=model, settings={})
                except EvaluationRefused as refused:
                    self.refused_evaluations[model.pk] = str(refused)
                    self._say(f"{name}'s evaluation refused: {refused}")

    def _progress(self, what: str, status: str, detail: str = "") -> None:
        if self.seen.get(what) != status:
            self.seen[what] = status
            self._say(f"{what}: {status.lower().replace('_', ' ')}{', ' if detail else ''}{detail}")

    def _say(self, text: str) -> None:
        print(f"[{clock(time.monotonic() - self.began)}] {text}", flush=True)

    def _over(self) -> bool:
        from bench.bench_training import job_of
        from training.models import EvaluationJob

        for model in self.models:
            job = job_of(model)
            if job.status in ("FAILED", "CANCELED"):
                continue
            if job.status != "COMPLETED":
                return False
            if model.pk not in self.evaluations and model.pk not in self.refused_evaluations:
                return False
        return not EvaluationJob.objects.filter(
            pk__in=[e.pk for e in self.evaluations.values()], status__in=EvaluationJob.ACTIVE
        ).exists()

    # The figures

    def report(self, unfinished: str | None) -> None:
        """The figures; ``unfinished``: why the evening ended early, if it did."""
        trained = self._jobs_table(unfinished)
        print(f"\nValidate, flooders (all {len(self.flooders)}): {self.flood.line()}")
        print(f"Validate, the bystander: {self.bystander.line()}")
        print(f"Home page, the bystander: {self.home.line()}")
        self._rescorings_line()
        evaluations = self._evaluations_table()
        p95 = self.bystander.p95_counting_refusals()
        validate_ok = p95 <= VALIDATE_TARGET
        print()
        print(
            f"{'PASS' if trained else 'FAIL'}  no job fails or starves: every job trained and "
            "completed, with at least one iteration"
        )
        print(
            f"{'PASS' if self.driving_within else 'FAIL'}  every racer's car drives within "
            f"{clock(DRIVES_TARGET)} of pressing Train"
        )
        print(
            f"{'PASS' if self.updated_within else 'FAIL'}  every job's first policy update lands "
            f"within {clock(UPDATE_TARGET)} of pressing Train"
        )
        if self.span:
            print(
                f"      the machine's total: {self.total_steps:,} steps in {clock(self.span)}, "
                f"from the first Train to the last job's end: {self.total_steps / self.span:.1f} "
                "steps/s (compare one job alone's)"
            )
        print(
            f"{'PASS' if validate_ok else 'FAIL'}  the bystander's Validate answers within "
            f"{VALIDATE_TARGET:g} s at p95: {p95:.2f} s (refused tries count as never answered)"
        )
        print(
            f"{evaluations}  no evaluation waits behind a re-scoring: each that waited while a "
            f"re-scoring ran was taken up within {EVALUATION_WAIT_TARGET:g} s"
        )

    def _jobs_table(self, unfinished: str | None) -> bool:
        from bench.bench_training import job_of
        from training.models import Iteration

        print(
            f"\n{'job':<14}{'queue wait':>11}{'drives at':>10}{'1st update':>11}{'training':>10}"
            f"{'iterations':>11}{'steps':>8}{'steps/s':>9}  status"
        )
        healthy, self.driving_within, self.updated_within = unfinished is None, True, True
        self.total_steps, ends = 0, []
        for model in self.models:
            job = job_of(model)
            rows = Iteration.objects.filter(job=job).order_by("number")
            wall = sum(row.wall_seconds for row in rows)
            rate = f"{sum(row.steps for row in rows) / wall:9.1f}" if wall else f"{'—':>9}"
            started = job.started_at
            wait = clock((started - job.created_at).total_seconds()) if started else "never"
            # From Train: the car drives when the clock starts (the trainer's first log line)
            drove = job.log_lines.filter(text__startswith="Training started").first()
            drives = (drove.at - job.created_at).total_seconds() if drove else None
            first = rows.first()
            updated = (first.created_at - job.created_at).total_seconds() if first else None
            self.driving_within &= drives is not None and drives <= DRIVES_TARGET
            self.updated_within &= updated is not None and updated <= UPDATE_TARGET
            self.total_steps += job.steps
            ends.append(job.finished_at)
            reason = f" ({job.failure_reason})" if job.failure_reason else ""
            print(
                f"{model.owner.username:<14}{wait:>11}{_clock_or(drives):>10}"
                f"{_clock_or(updated):>11}{clock(job.training_seconds):>10}"
                f"{job.iterations:>11}{job.steps:>8}{rate}  {job.status}{reason}"
            )
            healthy &= job.status == "COMPLETED" and job.iterations > 0
        if unfinished:
            print(f"{unfinished}: the jobs not completed above waited or trained on.")
        first = min(job_of(model).created_at for model in self.models)
        self.span = (max(ends) - first).total_seconds() if all(ends) else 0.0
        return healthy

    def _evaluations_table(self) -> str:
        """PASS, FAIL, or NOT MEASURED where no evaluation waited while a re-scoring ran."""
        from django.utils import timezone

        from analysis.models import Rescoring

        print(f"\n{'evaluation of':<14}{'wait':>8}  {'re-scoring running meanwhile':<30}status")
        measured, ok = False, True
        for model in self.models:
            name = model.owner.username
            if model.pk in self.refused_evaluations:
                print(
                    f"{name:<14}{'—':>8}  {'':<30}not started: {self.refused_evaluations[model.pk]}"
                )
                continue
            if model.pk not in self.evaluations:
                print(f"{name:<14}{'—':>8}  {'':<30}not asked (its training did not complete)")
                continue
            evaluation = self.evaluations[model.pk]
            evaluation.refresh_from_db()
            waited_until = evaluation.started_at
            overlapping = Rescoring.objects.filter(started_at__isnull=False).exclude(
                finished_at__lt=evaluation.created_at
            )
            if waited_until is not None:
                overlapping = overlapping.filter(started_at__lt=waited_until)
            rescoring = "yes" if overlapping.exists() else "no"
            wait = (waited_until or timezone.now()) - evaluation.created_at
            shown = clock(wait.total_seconds()) + ("" if waited_until else "+")
            print(f"{name:<14}{shown:>8}  {rescoring:<30}{evaluation.status}")
            measured |= rescoring == "yes"
            ok &= not (rescoring == "yes" and wait.total_seconds() > EVALUATION_WAIT_TARGET)
        return ("PASS" if ok else "FAIL") if measured else "NOT MEASURED"

    def _rescorings_line(self) -> None:
        from analysis.models import Rescoring

        rows = list(Rescoring.objects.all())
        ended = [row for row in rows if row.started_at and row.finished_at]
        busy = sum((row.finished_at - row.started_at).total_seconds() for row in ended)
        scored = sum(row.steps for row in ended)
        statuses = ", ".join(
            f"{sum(row.status == s for row in rows)} {s.lower()}"
            for s in ("DONE", "FAILED", "RUNNING", "QUEUED")
        )
        refused = ", ".join(
            f"{status or 'no answer'}: {n}" for status, n in sorted(self.rescore_refusals.items())
        )
        rate = f"{scored / busy:,.0f} steps/s while running" if busy else "none ended"
        print(
            f"Re-scorings, racer-1: {len(rows)} asked ({statuses}); {rate}; "
            f"refused: {refused or '0'}"
        )


def _clock_or(seconds: float | None) -> str:
    return clock(seconds) if seconds is not None else "never"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--racers", type=int, default=6, help="racers training one job each")
    parser.add_argument("--minutes", type=float, default=5.0, help="[min] each job trains")
    parser.add_argument("--flooders", type=int, default=2, help="racers flooding Validate")
    sizing = machine_sizing()  # what make run would choose here
    parser.add_argument(
        "--trainers",
        type=int,
        default=sizing.trainers,
        help="jobs training at once (make run's PITLANE_TRAINERS, chosen for the machine)",
    )
    parser.add_argument(
        "--simulations",
        type=int,
        default=sizing.simulations,
        help="simulation processes (make run's PITLANE_WORKER_CONCURRENCY, chosen likewise)",
    )
    parser.add_argument(
        "--console-rates",
        action="store_true",
        help="keep make run's rate limit on Validate (30 checks in 10 minutes per racer)",
    )
    parser.add_argument(
        "--patience",
        type=float,
        default=None,
        help="[min] after which the evening is given up (default: the queue's length in jobs "
        "times the training minutes plus 3, plus 10)",
    )
    arguments = parser.parse_args()
    if min(arguments.racers, arguments.trainers, arguments.simulations) < 1:
        parser.error("--racers, --trainers and --simulations take 1 or more")
    if arguments.patience is None:
        rounds = math.ceil(arguments.racers / arguments.trainers)
        arguments.patience = rounds * (arguments.minutes + 3) + 10
    settings = {"PITLANE_TRAINERS": str(arguments.trainers)}
    if not arguments.console_rates:
        settings["PITLANE_RATE_VALIDATE"] = LIFTED_VALIDATE_RATE
    with running_console(concurrency=arguments.simulations, settings=settings) as console:
        os.environ.update(console["env"])
        import django

        django.setup()
        print(
            f"A club evening: {arguments.racers} racers each train a model (DeepRacer's defaults, "
            f"{arguments.minutes:g} min) and evaluate it; {arguments.flooders} flood Validate"
            f"{'' if arguments.console_rates else ' (its rate limit lifted)'}; racer-1 re-scores. "
            f"The console: {arguments.trainers} trainer(s), {arguments.simulations} simulation "
            f"processes, 1 re-scoring, on {os.cpu_count()} cores.",
            flush=True,
        )
        evening = Evening(console["url"], arguments)
        try:
            unfinished = None if evening.run() else "Given up after --patience"
        except KeyboardInterrupt:
            unfinished = "Interrupted"
            print("\nInterrupted: the figures so far.")
        evening.report(unfinished)
    if unfinished == "Interrupted":
        sys.exit(130)


if __name__ == "__main__":
    main()
