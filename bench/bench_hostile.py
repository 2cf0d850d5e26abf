"""What a hostile reward function can take from a worker: `python -m bench.bench_hostile`.

Each attack is loaded into a sandbox set up as a rollout worker sets one up (the simulator, the
camera, a PPO policy, the 1-second call limit, the memory allowance) and drives one training
episode, as this process (standing in for the worker) samples its own resident memory every
10 ms. Printed: how the episode ended, how long it held the worker (target: the call's deadline,
``REWARD_CALL_LIMIT`` + ``GRACE``, where the attack blocks), and the worker's peak memory above
its baseline (target: under 100 MiB).
"""

from __future__ import annotations

import os
import threading
import time

import django

from rl import hyperparameters as hp
from rl.networks import SHALLOW
from sandbox import GRACE, Sandbox, SandboxFailure
from sandbox.protocol import pack

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
django.setup()  # the rollout worker's limits are read from where it keeps them

from jobs.rollouts import MEMORY_ALLOWANCE, REWARD_CALL_LIMIT  # noqa: E402

EVERYWHERE = """
import os, signal
def everywhere(data):
    for fd in range(0, 64):
        try:
            os.write(fd, data)
        except OSError:
            pass

def reward_function(params):
"""
ATTACKS = {
    "ignores its alarm and spins": "    signal.signal(signal.SIGALRM, signal.SIG_IGN)\n"
    "    while True:\n        pass",
    "forges progress frames, alarm ignored": "    signal.signal(signal.SIGALRM, signal.SIG_IGN)\n"
    f"    while True:\n        everywhere({pack({'type': 'progress', 'steps': 1})!r})",
    "breaks off a reply frame, alarm ignored": "    signal.signal(signal.SIGALRM, signal.SIG_IGN)\n"
    "    everywhere(b'\\x00\\x00\\x10\\x00x')\n    while True:\n        pass",
    "writes 50 MB to stderr per step, no newline": "    os.write(2, b'x' * 50_000_000)\n"
    "    return 1.0",
    "prints 100,000 lines per step": "    for _ in range(100_000):\n        print('z' * 300)\n"
    "    return 1.0",
    "floods its reply pipe with frames": "    for _ in range(1000):\n"
    "        everywhere(b'\\x00\\x01\\x00\\x00' + b'y' * 65536)\n    return 1.0",
    "takes 900 MB per step": "    global kept\n    kept = bytearray(900 * 1024 * 1024)\n"
    "    return 1.0",
}


def rss() -> int:
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS"))


def attack(body: str) -> tuple[str, float, float]:
    """(how the episode ended, seconds it held the worker, MiB above the baseline at peak)."""
    policy = {"algorithm": hp.PPO, "architecture": SHALLOW, "seed": 0}
    with Sandbox(
        env={"track": "rookie-loop"},
        policy=policy,
        call_timeout=REWARD_CALL_LIMIT,
        memory_allowance=MEMORY_ALLOWANCE,
    ) as sandbox:
        sandbox.load(EVERYWHERE + body)
        baseline = peak = rss()
        done = threading.Event()

        def sample() -> None:
            nonlocal peak
            while not done.wait(0.01):
                peak = max(peak, rss())

        sampler = threading.Thread(target=sample)
        sampler.start()
        started = time.monotonic()
        try:
            summary = sandbox.episode("explore")["summary"]
            outcome = f"drove {summary['steps']} steps"
        except SandboxFailure as failure:
            outcome = f"stopped: {failure.kind}"
        held = time.monotonic() - started
        done.set()
        sampler.join()
    return outcome, held, (peak - baseline) / 2**20


def main() -> None:
    print(f"Deadline of a blocking call: {REWARD_CALL_LIMIT + GRACE:g} s\n")
    print(f"{'attack':<46}{'outcome':<22}{'held [s]':>9}{'peak [MiB]':>12}")
    for name, body in ATTACKS.items():
        outcome, held, grown = attack(body)
        print(f"{name:<46}{outcome:<22}{held:>9.2f}{grown:>12.1f}", flush=True)


if __name__ == "__main__":
    main()
