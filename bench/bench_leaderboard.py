"""Leaderboard page renders with 100,000 submissions from 20,000 racers, on SQLite and PostgreSQL.

    python -m bench.bench_leaderboard [--requests 200]

Each database gets a fresh copy of the schema and one event with 20,000 racers who made five
submissions each (90% of them qualifying), ranked as the league ranks them. The benchmark then
renders the event's leaderboard through Django's full request stack (middleware, template,
context processors) as an anonymous visitor (first page, a middle page, the last page) and as a
signed-in racer far down the board (first page with their own row), and prints p50/p95 per page.

PostgreSQL runs as a throwaway cluster (initdb in a temporary folder, a free port, removed
afterwards): Debian's ``postgresql`` package provides it (``make bench`` installs it with apt).
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager

RACERS = 20_000
SUBMISSIONS_PER_RACER = 5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=200, help="renders per page")
    parser.add_argument("--child", help=argparse.SUPPRESS)  # a database URL: measure there
    args = parser.parse_args()
    if args.child:
        measure(args.child, args.requests)
        return
    print(f"Leaderboard: {RACERS * SUBMISSIONS_PER_RACER:,} submissions from {RACERS:,} racers")
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-") as folder:
        run_child(f"sqlite:///{folder}/bench.sqlite3", args.requests, "SQLite")
    with postgresql() as url:
        run_child(url, args.requests, "PostgreSQL")


def run_child(url: str, requests: int, label: str) -> None:
    print(f"\n== {label}", flush=True)
    env = {**os.environ, "DATABASE_URL": url, "DJANGO_SETTINGS_MODULE": "console.settings.dev"}
    subprocess.run(
        [
            sys.executable,
            "-m",
            "bench.bench_leaderboard",
            "--child",
            url,
            "--requests",
            str(requests),
        ],
        env=env,
        check=True,
    )


# PostgreSQL


@contextmanager
def postgresql():
    """A throwaway PostgreSQL cluster (``tests.cluster.Postgres``); its URL."""
    from tests.cluster import Postgres

    server = Postgres()
    try:
        yield server.url
    finally:
        server.remove()


# The measurement, in a process of its own per database


def measure(url: str, requests: int) -> None:
    import django

    django.setup()
    from django.conf import settings
    from django.core.management import call_command
    from django.db import connection
    from django.test import Client

    settings.ALLOWED_HOSTS = [*settings.ALLOWED_HOSTS, "testserver"]
    started = time.perf_counter()
    call_command("migrate", verbosity=0)
    call_command("loadtracks", verbosity=0, stdout=open(os.devnull, "w"))  # noqa: SIM115
    event, racers = populate()
    print(f"set up in {time.perf_counter() - started:.0f} s ({connection.vendor})")

    anonymous = Client()
    signed_in = Client()
    signed_in.force_login(racers[len(racers) * 3 // 4])
    pages = -(-event.rankings.count() // 100)
    url = event.get_absolute_url()
    cases = [
        ("anonymous, page 1", anonymous, url),
        (f"anonymous, page {pages // 2}", anonymous, f"{url}?page={pages // 2}"),
        (f"anonymous, page {pages} (last)", anonymous, f"{url}?page={pages}"),
        ("signed-in racer, page 1 + own row", signed_in, url),
        ("live refresh (table only)", anonymous, f"{url}?fragment=table"),
    ]
    print(f"{'page':38} {'p50 [ms]':>9} {'p95 [ms]':>9} {'max [ms]':>9}")
    for label, client, path in cases:
        for _ in range(5):  # warm the caches as a running server would be
            assert client.get(path).status_code == 200
        times = []
        for _ in range(requests):
            begin = time.perf_counter()
            response = client.get(path)
            times.append((time.perf_counter() - begin) * 1000)
            assert response.status_code == 200
        times.sort()
        p95 = times[int(0.95 * len(times)) - 1]
        print(f"{label:38} {statistics.median(times):9.1f} {p95:9.1f} {times[-1]:9.1f}")


def populate():
    """One open event with RACERS racers, SUBMISSIONS_PER_RACER each, ranked."""
    from datetime import timedelta

    from django.contrib.auth.models import User
    from django.db import transaction
    from django.utils import timezone

    from racing.models import Division, Event, Ranking, Season, Submission
    from training.models import Track

    rng = random.Random(7)  # noqa: S311 - made-up lap times
    now = timezone.now()
    with transaction.atomic():
        season = Season.objects.create(
            name="Bench season", year=now.year, starts_on=now.date(), ends_on=now.date()
        )
        event = Event.objects.create(
            season=season,
            name="Bench trial",
            slug="bench-trial",
            track=Track.objects.get(name="pitlane-oval"),
            division=Division.OPEN,
            opens_at=now - timedelta(days=10),
            closes_at=now + timedelta(days=10),
        )
        racers = User.objects.bulk_create(
            [User(username=f"racer{i:05d}", password="!") for i in range(RACERS)],  # noqa: S106
            batch_size=2000,
        )
        submissions = []
        for racer in racers:
            skill = rng.uniform(9_000, 30_000)
            for _ in range(SUBMISSIONS_PER_RACER):
                qualified = rng.random() < 0.9
                score = round(skill * rng.uniform(0.95, 1.2))
                submissions.append(
                    Submission(
                        event=event,
                        racer=racer,
                        model_name=f"model-{racer.pk}",
                        status=Submission.Status.COMPLETED,
                        finished_at=now,
                        qualified=qualified,
                        score_ms=score if qualified else None,
                        laps_completed=3,
                        off_tracks=rng.randint(0, 4),
                    )
                )
        Submission.objects.bulk_create(submissions, batch_size=5000)
        best: dict[int, Submission] = {}
        for submission in Submission.objects.filter(event=event, qualified=True).order_by(
            "score_ms", "created_at", "pk"
        ):
            best.setdefault(submission.racer_id, submission)
        Ranking.objects.bulk_create(
            [
                Ranking(
                    event=event,
                    racer_id=racer_id,
                    submission=s,
                    model_name=s.model_name,
                    score_ms=s.score_ms,
                    submitted_at=s.created_at,
                    laps_completed=s.laps_completed,
                    off_tracks=s.off_tracks,
                )
                for racer_id, s in best.items()
            ],
            batch_size=5000,
        )
    ranked = {ranking.racer_id for ranking in event.rankings.all()}
    return event, [racer for racer in racers if racer.pk in ranked]


if __name__ == "__main__":
    main()
