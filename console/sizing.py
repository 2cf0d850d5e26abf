"""How many jobs one machine trains at once, chosen from its cores and the memory it has free.

``make run`` (``console.supervisor``) starts a training worker of ``trainers`` processes and a
simulation worker of ``simulations``; each job that trains holds one trainer and its rollout
workers (``model.workers``, 1 by default) for its whole run, so a machine with memory to spare
should train several racers' jobs at once rather than queue them. The settings
(``console.settings.base``) take their defaults from ``machine_sizing``, and the supervisor hands
its children the figures it chose, so the web process (which counts the free trainers for a
queued job's words) and the workers agree. Each setting given in the environment still wins.

What a job costs, measured on the 2-core dev box (2026-11-29, VmRSS): PyTorch alone 219 MiB; with
DeepRacer's default network built (``rl.policies.Policy.for_environment``, clipped PPO, the
shallow CNN) 396 MiB; after three Adam updates of 64 observations 672 MiB. A Django and Celery
process with the training tasks imported holds 305 MiB. So a trainer is taken as 1 GiB (its
iteration's episodes included), and a rollout worker as 450 MiB (its Celery process, and its
sandbox child: 105 MiB with 8 cars and no PyTorch, its policy served by the machine's policy
server, ``bench.bench_policy_server``) plus 28 MiB a car (an environment and its episode:
``PITLANE_CARS_PER_WORKER``'s note). The reserve holds the policy server too (PyTorch, 400 MiB,
and a network of a few tens of MiB a job). No Django here: the settings import it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

MiB = 2**20
GiB = 2**30
RESERVE = 3 * GiB // 2  # [bytes] the web server, Redis, the policy server, the supervisor, the OS
TRAINER = 1 * GiB  # [bytes] a trainer process
ROLLOUT_WORKER = 450 * MiB  # [bytes] a simulation process with its sandbox child, no car
CAR = 28 * MiB  # [bytes] a car a rollout worker drives
CARS = 8  # a rollout worker's cars where memory allows: a batched forward pass (see settings)
SPARE_SIMULATIONS = 2  # simulation processes beside the jobs' rollouts: evaluations and races
MAX_TRAINERS = 8  # past it a job's share of the cores shrinks more than its wait does
TRAINERS_PER_CORE = 4  # a trainer waits for its rollouts most of an iteration, and they for it


@dataclass(frozen=True)
class Sizing:
    """What ``make run`` starts on a machine, and what it was chosen from."""

    cores: int
    available: int  # [bytes] memory free for Pitlane when it was chosen
    trainers: int  # jobs that train at once (PITLANE_TRAINERS)
    simulations: int  # simulation processes (PITLANE_WORKER_CONCURRENCY)
    cars: int  # cars a rollout worker drives (PITLANE_CARS_PER_WORKER)
    trainer_threads: int  # PyTorch threads of a trainer (PITLANE_TRAINER_THREADS)

    def environment(self) -> dict[str, str]:
        """The variables that choose the same again in another process."""
        return {
            "PITLANE_TRAINERS": str(self.trainers),
            "PITLANE_WORKER_CONCURRENCY": str(self.simulations),
            "PITLANE_CARS_PER_WORKER": str(self.cars),
            "PITLANE_TRAINER_THREADS": str(self.trainer_threads),
        }

    def in_words(self) -> str:
        """What was chosen, for the operator who started ``make run``."""
        return (
            f"This machine: {_count(self.cores, 'core')}, {self.available / GiB:.1f} GiB of "
            f"memory free. Training {_count(self.trainers, 'job')} at once (PITLANE_TRAINERS), "
            f"{_count(self.simulations, 'simulation process', 'es')} for their cars, "
            f"evaluations and races (PITLANE_WORKER_CONCURRENCY), "
            f"{_count(self.cars, 'car')} a rollout worker (PITLANE_CARS_PER_WORKER); "
            "set any of them to choose otherwise."
        )


def machine_sizing(
    *,
    cores: int | None = None,
    available: int | None = None,
    environ: dict[str, str] | os._Environ | None = None,
) -> Sizing:
    """What to start on a machine of ``cores`` with ``available`` bytes of memory free (this
    machine's when not given): as many trainers as the memory holds with a rollout worker each,
    beside the reserve and the spare simulation processes, at most ``TRAINERS_PER_CORE`` a core
    and ``MAX_TRAINERS``, at least 1; simulation processes for each trainer's rollout worker and
    ``SPARE_SIMULATIONS`` more, at least one a core and 2; ``CARS`` cars a rollout worker unless
    one job's do not fit, then as many as do, at least 1; and the cores shared among the trainers
    as their threads. A whole number in ``environ`` (``os.environ`` when not given) for
    ``PITLANE_TRAINERS``, ``PITLANE_WORKER_CONCURRENCY``, ``PITLANE_CARS_PER_WORKER`` or
    ``PITLANE_TRAINER_THREADS`` wins, and what depends on it follows it; the settings check its
    range."""
    environ = os.environ if environ is None else environ
    cores = machine_cores() if cores is None else cores
    available = memory_available() if available is None else available
    budget = available - RESERVE - SPARE_SIMULATIONS * ROLLOUT_WORKER  # [bytes] for the jobs
    cars = _given(environ, "PITLANE_CARS_PER_WORKER")
    if cars is None:
        cars = min(CARS, max(1, (budget - TRAINER - ROLLOUT_WORKER) // CAR))
    trainers = _given(environ, "PITLANE_TRAINERS")
    if trainers is None:
        job = TRAINER + ROLLOUT_WORKER + cars * CAR
        trainers = min(MAX_TRAINERS, TRAINERS_PER_CORE * cores, max(1, budget // job))
    simulations = _given(environ, "PITLANE_WORKER_CONCURRENCY")
    if simulations is None:
        simulations = max(trainers + SPARE_SIMULATIONS, cores, 2)
    threads = _given(environ, "PITLANE_TRAINER_THREADS")
    if threads is None:  # the most: each trainer shares the cores among the jobs training now
        threads = cores
    return Sizing(cores, available, trainers, simulations, cars, threads)


def machine_cores() -> int:
    """The cores this process may run on (its affinity: a container's or ``taskset``'s)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def memory_available(
    meminfo: Path = Path("/proc/meminfo"), cgroup: Path = Path("/sys/fs/cgroup")
) -> int:
    """[bytes] The memory free to start processes in: the kernel's MemAvailable (what it can give
    without swapping; MemTotal where it says none), within the memory limit of this process's
    control group where one is set (a container's); 4 GiB where neither can be read."""
    fields = {}
    try:
        for line in meminfo.read_text().splitlines():
            name, _, value = line.partition(":")
            fields[name] = int(value.split()[0]) * 1024  # kB
    except (OSError, ValueError, IndexError):
        pass
    available = fields.get("MemAvailable", fields.get("MemTotal", 4 * GiB))
    try:
        limit = (cgroup / "memory.max").read_text().strip()
        used = int((cgroup / "memory.current").read_text())
    except (OSError, ValueError):
        return available
    if limit.isdigit():
        available = min(available, max(int(limit) - used, 0))
    return available


def _given(environ, name: str) -> int | None:
    """The whole number set for ``name``; None when unset, blank or not a number (the settings
    then name the mistake)."""
    try:
        return int(environ.get(name, "").strip())
    except ValueError:
        return None


def _count(number: int, noun: str, plural: str = "s") -> str:
    return f"{number} {noun}" if number == 1 else f"{number} {noun}{plural}"
