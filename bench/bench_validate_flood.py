"""A bystander's Validate under a flood of slow reward functions from four racers.

    python -m bench.bench_validate_flood [--flooders 4] [--checks 8] [--pause 3]

What Validate does once its view has parsed the form: ``rewards.reward_validate`` of the code,
run by a checker of the web process's pool (``training.checkers``, ``PITLANE_CHECKERS`` of them
and ``PITLANE_CHECKS_WAITING`` places in line), in the racer's turn. ``--flooders`` racers each
keep as many checks in the pool as they may (``checkers.RACER_PLACES``), sending the next as soon
as one ends or, when refused, half a second later; their function takes every second it is
allowed, at load and at every sample (it catches the sandbox's time limit and returns). Once the
flood runs, a bystander validates DeepRacer's follow-the-centre-line example ``--checks`` times,
``--pause`` seconds after each answer. It prints each answer's time, the p50 and the worst, how
many times the bystander was refused (Busy: the view's 503), and the flood's checks. Run it in
another checkout (``git archive <commit> | tar -x -C DIR``, this file copied in) for a before.
"""

from __future__ import annotations

import argparse
import os
import statistics
import threading
import time

# Every second the sandbox allows: at load, and at each sample call.
HOSTILE = """
try:
    while True:
        pass
except BaseException:
    pass


def reward_function(params):
    try:
        while True:
            pass
    except BaseException:
        return 1.0
"""
TRACK = "rookie-loop"
REFUSED_PAUSE = 0.5  # [s] a flooder waits after a refusal
WARM_UP = 5.0  # [s] of flood before the bystander's first check


def flood(racer: str, stop: threading.Event, done: list[float]) -> None:
    """One of ``racer``'s places: a check after another until ``stop``."""
    from training import checkers, rewards

    while not stop.is_set():
        try:
            future = checkers.pool().submit(
                lambda: rewards.reward_validate(source=HOSTILE, track=TRACK), racer=racer
            )
        except checkers.Busy:
            time.sleep(REFUSED_PAUSE)
            continue
        future.result()
        done.append(time.monotonic())


def bystander(checks: int, pause: float) -> tuple[list[float], int]:
    """The bystander's answer times (an answer that was a refusal is not one: they try again
    at once and the time runs on) and how many refusals they met."""
    from training import checkers, rewards

    source = rewards.example_source("follow_centre_line")
    answers, refused = [], 0
    for _ in range(checks):
        started = time.monotonic()
        while True:
            try:
                future = checkers.pool().submit(
                    lambda: rewards.reward_validate(source=source, track=TRACK), racer="bystander"
                )
                break
            except checkers.Busy:
                refused += 1
                time.sleep(REFUSED_PAUSE)
        assert future.result().valid
        answers.append(time.monotonic() - started)
        print(f"  bystander answered in {answers[-1]:5.1f} s", flush=True)
        time.sleep(pause)
    return answers, refused


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flooders", type=int, default=4)
    parser.add_argument("--checks", type=int, default=8, help="the bystander's")
    parser.add_argument("--pause", type=float, default=3.0, help="[s] after each answer")
    args = parser.parse_args()
    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
    import django

    django.setup()
    from django.conf import settings

    from training import checkers, rewards

    print(
        f"{settings.PITLANE_CHECKERS} checkers, {settings.PITLANE_CHECKS_WAITING} places in "
        f"line, {checkers.RACER_PLACES} a racer; {rewards.SAMPLE_TIMEOUT:g} s a sample; "
        f"{args.flooders} flooders, {os.cpu_count()} cores"
    )
    stop, flooded = threading.Event(), []
    threads = [
        threading.Thread(target=flood, args=(f"flooder-{n}", stop, flooded), daemon=True)
        for n in range(args.flooders)
        for _ in range(checkers.RACER_PLACES)
    ]
    started = time.monotonic()
    for thread in threads:
        thread.start()
    time.sleep(WARM_UP)
    try:
        answers, refused = bystander(args.checks, args.pause)
    finally:
        stop.set()
    took = time.monotonic() - started
    print(
        f"bystander: p50 {statistics.median(answers):.1f} s, worst {max(answers):.1f} s, "
        f"within 10 s {sum(a <= 10 for a in answers)} of {len(answers)}, refused {refused} times; "
        f"flood: {len(flooded)} checks in {took:.0f} s"
    )
    for thread in threads:  # each ends once its check in hand does
        thread.join()


if __name__ == "__main__":
    main()
