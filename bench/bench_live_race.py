"""A live race's audience: frame latency with 50 watchers, and the broadcast's lap timer against
the simulated lap times: `python -m bench.bench_live_race [--watchers 50] [--laps 3]`.

Starts the console as `make run` does, makes a public event on the Pitlane Oval, a racer with a
ready model (tests.helpers.models' straight-ahead policy, which leaves the track at each
bend and is put back), opens the event's live race, queues the model and launches its turn: a
simulation worker drives ``--laps`` laps in real time (racing.live_races).

- Latency: ``--watchers`` websocket clients through Daphne, as visitors who have not logged in
  (the event is public), each acknowledging each frame as the race page does once drawn; from
  the frame's render in the simulation to its arrival, p50 and p95 over every frame every
  watcher got (bench_live's viewers, in a process of their own at the lowest CPU priority).
- The lap timer: Chromium shows the broadcast page; as each lap ends, the page's running timer
  (the frames' simulated lap time, run on between frames: static/racing/turn.js) is read at the
  line and set against the lap's simulated time (the trial's time_ms, penalties apart), which the
  timer then stops on. Printed: each lap's difference and the largest.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import statistics
import time
from concurrent.futures import ThreadPoolExecutor

from bench.bench_live import Viewer, audience
from bench.stack import running_console

# Read the running timer as each lap's line comes: the page notes its reading at the line
# (data-at-line) before the timer stops on the lap's time.
RECORD_LAPS = """
window.lapsSeen = [];
new MutationObserver((changes) => {
  for (const change of changes) for (const node of change.addedNodes) {
    const timer = document.querySelector("[data-timer]");
    window.lapsSeen.push({lap: node.dataset.lap, timer: timer.dataset.atLine});
  }
}).observe(document.querySelector("[data-laps]"), {childList: true});
"""


def laptime_ms(text: str) -> int:
    minutes, rest = text.split(":")
    return round((int(minutes) * 60 + float(rest)) * 1000)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--watchers", type=int, default=50)
    parser.add_argument("--laps", type=int, default=3)
    args = parser.parse_args()
    with running_console(concurrency=3) as console:
        os.environ.update(console["env"])
        # Playwright's sync API runs an event loop in this thread; the ORM calls between its
        # calls are still plain synchronous ones (as in tests/browser/conftest.py)
        os.environ.setdefault("DJANGO_ALLOW_ASYNC_UNSAFE", "true")
        import django

        django.setup()
        from django.utils import timezone
        from playwright.sync_api import sync_playwright

        from bench.bench_training import bench_racer
        from racing import live_races
        from racing.models import Event, Season, Submission
        from tests.helpers.models import ready_model
        from training.models import EvaluationTrial, Track
        from training.services import tracks_sync

        tracks_sync()
        now = timezone.now()
        season = Season.objects.create(
            name="Bench", year=now.year, starts_on=now.date(), ends_on=now.date()
        )
        event = Event.objects.create(
            season=season,
            name="Live bench",
            slug="live-bench",
            opens_at=now,
            closes_at=now + timezone.timedelta(days=1),
            laps_required=1,
            laps_to_drive=args.laps,
            track=Track.objects.get(name="pitlane-oval"),
        )
        racer = bench_racer()
        staff = bench_racer("staff")
        session = live_races.live_session_open(event=event, facilitator=staff)
        live_races.live_entry_join(session=session, racer=racer, model=ready_model(racer))

        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(
                executable_path=shutil.which("chromium"), args=["--no-sandbox"]
            )
            page = browser.new_page(viewport={"width": 1280, "height": 720})
            page.goto(f"{console['url']}/events/{event.slug}/broadcast/")
            page.wait_for_selector("body[data-listening=true]")
            page.evaluate(RECORD_LAPS)

            # announcing the turn sends to the channel layer, which may not run in the thread of
            # Playwright's event loop
            with ThreadPoolExecutor(max_workers=1) as thread:
                turn = thread.submit(live_races.live_turn_launch, session=session).result()
            evaluation = turn.submission.evaluation_id
            url = console["url"].replace("http", "ws", 1) + f"/ws/live-turns/{evaluation}/"
            context = multiprocessing.get_context("spawn")
            pipe, theirs = context.Pipe()
            origin = {"Origin": console["url"]}  # as a browser on the page sends it
            crowd = context.Process(target=audience, args=(url, origin, args.watchers, theirs))
            crowd.start()
            while Submission.objects.get(pk=turn.submission_id).is_active:
                time.sleep(0.5)
            pipe.send("stop")
            viewers: list[Viewer] = pipe.recv()
            crowd.join(30)
            seen = page.evaluate("window.lapsSeen")
            browser.close()

        latencies = sorted(1000 * x for viewer in viewers for x in viewer.latencies)
        frames = [viewer.frames for viewer in viewers]
        p95 = latencies[int(0.95 * (len(latencies) - 1))]
        print(
            f"{args.watchers} watchers of a live turn ({args.laps} laps of the Pitlane Oval in "
            f"real time): {len(latencies):,} frames, {min(frames)}-{max(frames)} a watcher; "
            f"latency p50 {statistics.median(latencies):.0f} ms, p95 {p95:.0f} ms"
        )
        trials = EvaluationTrial.objects.filter(evaluation_id=evaluation).order_by("number")
        differences = []
        for trial, shown in zip(trials, seen, strict=False):
            difference = laptime_ms(shown["timer"]) - trial.time_ms
            differences.append(abs(difference))
            print(
                f"lap {trial.number}: simulated {trial.time_ms / 1000:.3f} s, the broadcast's "
                f"timer {shown['timer']} ({difference:+d} ms)"
            )
        if differences:
            print(f"the broadcast's lap timer: within {max(differences)} ms of the simulated laps")


if __name__ == "__main__":
    main()
