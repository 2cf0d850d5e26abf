"""What the sandbox costs: `python -m bench.bench_sandbox` (or `make bench`).

The same loop twice, on one core: the episode loop training runs (``rl.episode.drive``: the
simulator with its camera, a PPO policy of DeepRacer's 3-layer CNN exploring, a typical reward
function, our "prevent zig-zag" example, which reads several params and branches), once in this
process and once inside a sealed sandbox child, as a rollout worker drives it (``Sandbox.episode``,
the episode's experience encoded and sent back). The sandbox adds the reward function's process
of its own (a round trip per call), seccomp's check of each syscall, progress messages and the
episode's encoding.

``--cars 1 4 8``: the rollouts alone with that many cars in one sandbox (``Sandbox(cars=...)``,
driven as a rollout worker drives them: every idle car starts an episode, each step one batched
forward pass for all): steps/s of all the cars together, on the same one core. With
``--served``, each beside the same with the policy served to the child by a machine's policy
server (``rl.policy_server``, started for the bench on that same core): the cost of the round
trip a step through shared memory; ``--served cuda``, the server on the GPU.

``--starts N``: what starting costs, the CPU seconds (median of N) the whole machine spends on
a sandbox child started, given a reward function and closed, as a reward check starts one (this
process's side, the child's and its reward process's: the machine's busy time, so run it on an
idle machine), on a worker process's zygote started (once a process: ``sandbox.zygote``), and on
a policy of DeepRacer's 3-layer PPO built to be driven with weights loaded at once
(``Policy.build(loading=True)``, as an evaluation, an export and the policy server build theirs)
against one built with its own first weights.
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import tempfile
import time
from pathlib import Path

import gymnasium

import simulator
from rl import episode
from rl.policies import Policy
from rl.policy_lease import PolicyLease
from sandbox import CHILD_ENVIRONMENT, MiB, Sandbox
from sandbox.spawner import Zygote
from training.rewards import EXAMPLES, example_source

STEPS = 3000
ROUNDS = 3
TRACK = "rookie-loop"
POLICY = {"algorithm": "clipped_ppo", "architecture": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"}
SOCKET = str(Path(tempfile.mkdtemp(prefix="bench-")) / "policy.sock")  # the bench's own server


def reward_source() -> str:
    return example_source("prevent_zig_zag")


def in_process() -> float:
    import torch

    torch.set_num_threads(1)  # as the sandbox child
    namespace: dict = {}
    exec(compile(reward_source(), "<reward_function>", "exec"), namespace)  # noqa: S102
    env = gymnasium.make(simulator.ENV_ID, track=TRACK, reward_fn=namespace["reward_function"])
    env.reset(seed=0)
    policy = Policy.build(
        POLICY["algorithm"], POLICY["architecture"], env.observation_space, env.action_space
    )
    episode.drive(env, policy)  # warm-up
    steps, started = 0, time.perf_counter()
    while steps < STEPS:
        steps += len(episode.drive(env, policy).rewards)
    elapsed = time.perf_counter() - started
    env.close()
    return steps / elapsed


@functools.cache
def weights() -> bytes:
    """One policy's first weights, which both places drive with."""
    from rl.learner import weights_bytes

    policy = Policy.for_environment(**POLICY, environment={"track": TRACK})
    return weights_bytes(policy.weights_module.state_dict())


def in_sandbox(cars: int = 1, steps_wanted: int = STEPS, device: str | None = None) -> float:
    """Steps/s of all the cars together, from the steps the child says it has driven as it
    drives (its progress messages): every step driven in the timed window counts, of episodes
    that end in it or not, and none driven before it."""
    seen: list[tuple[int, float]] = []  # (steps driven by all the cars so far, when told)

    def progress(steps: int) -> None:
        seen.append((steps, time.perf_counter()))

    with Sandbox(
        env={"track": TRACK},
        cars=cars,
        policy=POLICY,
        policy_lease=None if device is None else PolicyLease(SOCKET, device),
        memory_allowance=1024 * MiB,
        car_memory=384 * MiB,
    ) as sandbox:
        sandbox.load(reward_source())
        sandbox.set_weights(1, weights())  # a served child's server has none until given
        driving = sandbox.episode(start=cars)["driving"]  # warm-up
        seen.clear()
        while not seen or seen[-1][0] - seen[0][0] < steps_wanted:
            driving = sandbox.episode(on_progress=progress, start=cars - driving)["driving"]
    (first, started), (last, ended) = seen[0], seen[-1]
    return (last - first) / (ended - started)


def cars_alone(options: argparse.Namespace) -> None:
    """``--cars``' figures: steps/s with the policy in the child (and, ``--served``, served)."""
    served = {f"served ({options.served})": options.served} if options.served else {}
    places = {"in the child": None, **served}
    print(f"{'cars in one sandbox, one core':<32}" + "".join(f"{p:>20}" for p in places))
    for cars in options.cars:
        rates = []
        for device in places.values():
            runs = [in_sandbox(cars, options.steps, device) for _ in range(options.rounds)]
            rates.append(statistics.median(runs))
        print(f"{cars:<32}" + "".join(f"{rate:>20,.0f}" for rate in rates))


def machine_cpu() -> float:
    """[s] of CPU the whole machine has been busy (``/proc/stat``). A sandbox child is its
    zygote's, not this process's, so only the machine sees all a start costs: this process's
    side, the child's and its reward process's."""
    with open("/proc/stat") as stat:
        ticks = [int(field) for field in stat.readline().split()[1:]]
    return (sum(ticks) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK")  # less idle, iowait


def starts(count: int) -> None:
    def child() -> float:
        before = machine_cpu()
        with Sandbox(samples={"track": TRACK, "direction": "counterclockwise"}) as sandbox:
            sandbox.load(EXAMPLES[0].source)
        return machine_cpu() - before

    def zygote() -> float:
        before = machine_cpu()
        started = Zygote(CHILD_ENVIRONMENT)
        started.spawn().stdin.close()  # a child that exits at once
        started.stop()
        return machine_cpu() - before

    def policy(loading: bool) -> float:
        started = time.process_time()
        Policy.for_environment(**POLICY, environment={"track": TRACK}, loading=loading)
        return time.process_time() - started

    policy(False)  # PyTorch loaded and warmed before any is timed
    child()  # and this process's zygote started
    figures = {
        "a sandbox child started, as a reward check starts one": [child() for _ in range(count)],
        "a worker process's zygote started (once)": [zygote() for _ in range(count)],
        "a policy built with its own first weights": [policy(False) for _ in range(count)],
        "a policy built for the weights it loads": [policy(True) for _ in range(count)],
    }
    print(f"{'start':<56}{'CPU s':>8}")
    for name, seconds in figures.items():
        print(f"{name:<56}{statistics.median(seconds):>8.3f}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cars", type=int, nargs="+", help="rollouts alone, with these cars")
    parser.add_argument("--steps", type=int, default=STEPS, help="steps timed per figure")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help="figures a median is of")
    parser.add_argument(
        "--served",
        nargs="?",
        const="cpu",
        choices=("cpu", "cuda"),
        help="and with the policy served from this device (cpu)",
    )
    parser.add_argument("--starts", type=int, help="what starting costs, median of so many")
    options = parser.parse_args()
    if options.starts:
        starts(options.starts)
        return
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # the child inherits it
    if options.cars:
        cars_alone(options)
        return
    direct = statistics.median(in_process() for _ in range(ROUNDS))
    sandboxed = statistics.median(in_sandbox() for _ in range(ROUNDS))
    print(f"{'loop':<52}{'steps/s':>10}")
    print(f"{'episodes (simulator, policy, reward), in process':<52}{direct:>10,.0f}")
    print(f"{'episodes (simulator, policy, reward), in the sandbox':<52}{sandboxed:>10,.0f}")
    print(f"{'cost of the sandbox':<52}{(1 - sandboxed / direct) * 100:>9.1f}%")


if __name__ == "__main__":
    main()
