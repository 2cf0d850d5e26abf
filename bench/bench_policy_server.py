"""The machine's policy server against a policy in each sandbox child:
`python -m bench.bench_policy_server --workers 2 --cars 8`.

``--workers`` sandbox children of ``--cars`` cars each drive at once, as that many rollout
workers of one job do on a machine (each child on a thread of this process, which relays as a
worker does), first with the policy in each child (``PITLANE_ROLLOUT_DEVICE=child``: each child
runs its own forward pass of its cars on one thread), then served by the machine's policy server
(``rl.policy_server``: one batched pass for every child that rang). It prints the steps/s of all
the cars together (from the children's progress messages, past a warm-up), the server's passes
and the rows of an average one, and the memory each child maps (resident), median of
``--rounds`` (the two taken in turn, round by round). ``--jobs 2`` gives each half of the
children a job (and weights) of its own.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import threading
import time
from pathlib import Path

from rl.learner import weights_bytes
from rl.policies import Policy
from rl.policy_lease import PolicyLease
from sandbox import MiB, Sandbox

TRACK = "rookie-loop"
POLICY = {"algorithm": "clipped_ppo", "architecture": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"}
REWARD = "def reward_function(params):\n    return 1.0 if params['all_wheels_on_track'] else 1e-3\n"


def resident(pid: int) -> int:
    """[bytes] of memory process ``pid`` holds (VmRSS)."""
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def drive(sandbox: Sandbox, steps: int, seen: list, start: threading.Barrier) -> None:
    """Drive ``sandbox``'s cars until ``steps`` are driven past the barrier, noting every
    progress message (steps so far, when)."""
    mine: list[tuple[int, float]] = []
    driving = sandbox.episode(start=sandbox.cars)["driving"]  # the warm-up
    start.wait()
    while not mine or mine[-1][0] - mine[0][0] < steps:
        reply = sandbox.episode(
            on_progress=lambda n: mine.append((n, time.perf_counter())),
            start=sandbox.cars - driving,
        )
        driving = reply["driving"]
    seen.append(mine)


def round_of(options: argparse.Namespace, socket: str | None, weights: list[bytes]) -> dict:
    """One round: steps/s of all the children's cars together, and their memory."""
    sandboxes = []
    for worker in range(options.workers):
        job = worker % options.jobs
        lease = PolicyLease(socket, options.device) if socket else None
        sandbox = Sandbox(
            env={"track": TRACK},
            cars=options.cars,
            policy={**POLICY, "seed": worker * options.cars, "job": job + 1},
            policy_lease=lease,
            memory_allowance=1024 * MiB,
            car_memory=384 * MiB,
        )
        sandbox.start()
        sandbox.load(REWARD)
        sandbox.set_weights(1, weights[job])
        sandboxes.append(sandbox)
    try:
        seen: list[list[tuple[int, float]]] = []
        start = threading.Barrier(options.workers)
        threads = [
            threading.Thread(target=drive, args=(sandbox, options.steps, seen, start))
            for sandbox in sandboxes
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        memory = [resident(sandbox._process.pid) for sandbox in sandboxes]
        stats = sandboxes[0].policy_lease.stats() if socket else {}
    finally:
        for sandbox in sandboxes:
            sandbox.close()
    # Every child's steps from its first progress message to its last, over the time from the
    # first child's first to the last child's last: a child left driving alone counts against it.
    began, ended = min(mine[0][1] for mine in seen), max(mine[-1][1] for mine in seen)
    steps = sum(mine[-1][0] - mine[0][0] for mine in seen)
    return {"rate": steps / (ended - began), "memory": statistics.mean(memory), **stats}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--workers", type=int, default=2, help="sandbox children at once")
    parser.add_argument("--cars", type=int, default=8, help="cars a child")
    parser.add_argument("--jobs", type=int, default=1, help="jobs the children are shared among")
    parser.add_argument("--steps", type=int, default=2000, help="steps a child drives, timed")
    parser.add_argument("--rounds", type=int, default=3, help="figures a median is of")
    parser.add_argument("--device", default="cpu", choices=("cpu", "cuda", "auto"))
    options = parser.parse_args()
    built = [Policy.for_environment(**POLICY, environment={"track": TRACK}) for _ in range(2)]
    weights = [weights_bytes(policy.weights_module.state_dict()) for policy in built]
    socket = str(Path(tempfile.mkdtemp(prefix="bench-")) / "policy.sock")
    print(
        f"{options.workers} children of {options.cars} cars, {options.jobs} job(s), "
        f"{options.steps:,} steps a child timed, median of {options.rounds}"
    )
    print(f"{'policy':<30}{'steps/s':>10}{'child MiB':>12}{'rows a pass':>13}")
    places = {"in each child": None, f"served ({options.device})": socket}
    rounds: dict[str, list[dict]] = {name: [] for name in places}
    for _ in range(options.rounds):  # in turn, so that the machine's drift touches both alike
        for name, place in places.items():
            rounds[name].append(round_of(options, place, weights))
    for name, place in places.items():
        rate = statistics.median(r["rate"] for r in rounds[name])
        memory = statistics.median(r["memory"] for r in rounds[name]) / MiB
        rows = ""
        if place:
            last = rounds[name][-1]
            rows = f"{last['rows'] / max(last['passes'], 1):.1f}"
        print(f"{name:<30}{rate:>10,.0f}{memory:>12,.0f}{rows:>13}")
    Path(socket).unlink(missing_ok=True)


if __name__ == "__main__":
    main()
