"""The API at a club's size: `python -m bench.bench_api` (issue 58).

Starts the whole console as `make run` does (bench.stack: its Redis, Celery workers, Daphne,
SQLite, in a scratch directory) with the API's rate lifted, then:

1. gives one racer ``--models`` models (1,000) and times the list and detail endpoints over HTTP
   with the racer's token (200 requests each after 10 warm-ups): p50 and p95 [ms];
2. makes a model with DeepRacer's default network and a trained checkpoint, and moves its
   virtual archive (its best and last checkpoints) both ways, three times each: downloaded by
   ``pitlane_client`` and by the model page's link, imported by ``pitlane_client`` and by the
   import page's form (signed in, with its CSRF token): MB/s each, the import's counting the
   whole import (the archive read, its weights checked, the model made);
3. fuzzes the OpenAPI document with schemathesis's command line (``--examples`` per
   operation, every check but positive-data acceptance, as tests/api/test_fuzzed.py) and prints
   its summary: how many requests it sent and whether any failed (PASS needs 2,000 or more and
   none).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import requests

from bench.bench_club_evening import Browser
from bench.bench_console import percentile
from bench.stack import running_console

REQUESTS, WARM = 200, 10
REPEATS = 3  # of each transfer
LIFTED = {"PITLANE_RATE_API": "1000000/10m", "PITLANE_RATE_IMPORT": "1000/h"}


def racer(name: str):
    """A racer and a token of theirs with every racer's scope."""
    from django.contrib.auth import get_user_model

    from accounts.tokens import token_create

    user = get_user_model().objects.create_user(name, password="!")  # noqa: S106
    scopes = ["read", "train", "race"]
    return user, token_create(owner=user, name="bench", scopes=scopes, days=7)[1]


def racer_with_models(count: int):
    """A racer with ``count`` READY models (rows only) and a token; (racer, token, model ids)."""
    from rl import hyperparameters
    from training import configuration
    from training.models import RLModel
    from training.rewards import EXAMPLES

    racer_made, secret = racer("bench-racer")
    settings = {
        "track": "rookie-loop",
        "hyperparameters": hyperparameters.defaults("clipped_ppo"),
        "reward_function": EXAMPLES[0].source,
    }
    checked = configuration.check(
        {**settings, "name": "m"}, owner=racer_made, validate_reward=False
    )
    ready = RLModel.Status.READY
    rows = [
        RLModel(**{**checked.row(), "name": f"model-{n:04d}"}, owner=racer_made, status=ready)
        for n in range(count)
    ]
    RLModel.objects.bulk_create(rows, batch_size=500)
    ids = list(RLModel.objects.filter(owner=racer_made).values_list("pk", flat=True))
    return secret, ids


def timed(url: str, token: str) -> tuple[float, float]:
    """p50 and p95 [ms] of ``REQUESTS`` GETs of ``url``."""
    session = requests.Session()
    session.headers["Authorization"] = f"Bearer {token}"
    samples = []
    for attempt in range(WARM + REQUESTS):
        started = time.perf_counter()
        session.get(url, timeout=60).raise_for_status()
        if attempt >= WARM:
            samples.append((time.perf_counter() - started) * 1000)
    return percentile(samples, 0.5), percentile(samples, 0.95)


def transfers(base: str, work: Path) -> None:
    """MB/s of the virtual archive's download and import, by the client and by the pages, for
    a racer of their own (the other has a quota's worth of models)."""
    from django.conf import settings
    from pitlane_client import Client

    from tests.helpers.models import trained_model
    from training.models import RLModel

    mover, token = racer("bench-mover")
    model = trained_model(mover, "to-move", track="rookie-loop")  # DeepRacer's defaults
    client = Client(base, token, timeout=600)
    browser = Browser(base, mover)
    archive = client.download(model.pk, "virtual", work)
    size = archive.stat().st_size / 1e6
    print(f"The virtual archive: {size:.1f} MB (a camera model's best and last checkpoints)")

    def rate(label: str, run) -> None:
        """The best of ``REPEATS`` runs, printed."""
        best = []
        for attempt in range(REPEATS):
            started = time.perf_counter()
            run(attempt)
            best.append(size / (time.perf_counter() - started))
        print(f"{label:<44}{max(best):>10.1f} MB/s", flush=True)

    rate("download, pitlane_client", lambda _: client.download(model.pk, "virtual", work))

    def page_download(_):
        got = browser.session.get(f"{base}/models/{model.pk}/download/virtual/", timeout=600)
        got.raise_for_status()
        assert len(got.content) > 0

    rate("download, the model page", page_download)
    rate("import, pitlane_client", lambda n: client.import_archive(archive, f"by-api-{n}"))

    def form_import(n):
        with archive.open("rb") as file:
            answer = browser.session.post(
                f"{base}/models/import/",
                data={"name": f"by-form-{n}"},
                files={"archive": (archive.name, file, "application/gzip")},
                headers={"X-CSRFToken": browser.session.cookies[settings.CSRF_COOKIE_NAME]},
                timeout=600,
            )
        assert answer.ok and RLModel.objects.filter(name=f"by-form-{n}").exists(), (
            answer.status_code
        )

    rate("import, the import page", form_import)


def fuzz(base: str, token: str, examples: int) -> tuple[int, bool]:
    """schemathesis's run over the document: (requests sent, whether all passed)."""
    command = [
        str(Path(sys.executable).with_name("schemathesis")),
        "run",
        f"{base}/api/v1/schema",
        "--header",
        f"Authorization: Bearer {token}",
        "--max-examples",
        str(examples),
        "--exclude-checks",
        "positive_data_acceptance",
        "--no-color",
    ]
    run = subprocess.run(command, capture_output=True, text=True, timeout=3600, check=False)
    found = run.stdout.find("FAILURES")
    summary = run.stdout[run.stdout.rfind("SUMMARY") :] if "SUMMARY" in run.stdout else run.stdout
    shown = run.stdout[found:] if found >= 0 else summary  # each failure, with its curl
    print(shown.strip()[-12000:])
    cases = re.search(r"Test cases:\s*([\d,]+) generated", summary)
    count = int(cases[1].replace(",", "")) if cases else 0
    return count, run.returncode == 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", type=int, default=1000)
    parser.add_argument("--examples", type=int, default=60, help="per operation, for the fuzz")
    arguments = parser.parse_args()
    with running_console(settings=LIFTED) as console, tempfile.TemporaryDirectory() as work:
        os.environ.update(console["env"])
        import django

        django.setup()
        base = console["url"]
        token, ids = racer_with_models(arguments.models)
        print(f"{arguments.models} models of one racer; {REQUESTS} requests each:")
        print(f"{'endpoint':<44}{'p50 [ms]':>10}{'p95 [ms]':>10}")
        for label, path in (
            ("GET /models (50 a page)", "/api/v1/models"),
            ("GET /models?status=READY&q=model-09", "/api/v1/models?status=READY&q=model-09"),
            ("GET /models?offset=950", "/api/v1/models?offset=950"),
            ("GET /models/{id}", f"/api/v1/models/{ids[len(ids) // 2]}"),
            ("GET /models/{id}/iterations", f"/api/v1/models/{ids[0]}/iterations"),
        ):
            p50, p95 = timed(base + path, token)
            print(f"{label:<44}{p50:>10.1f}{p95:>10.1f}", flush=True)
        transfers(base, Path(work))
        count, passed = fuzz(base, token, arguments.examples)
        verdict = "PASS" if passed and count >= 2000 else "FAIL"
        said = "none" if passed else "some"
        print(f"{verdict}: schemathesis sent {count:,} requests; {said} failed")


if __name__ == "__main__":
    main()
