"""The machine's policy server (``rl.policy_server``), serving sandbox children their policy
through shared memory (``Sandbox(policy_lease=...)``, ``sandbox.served``): children of two jobs
served together drive the episodes each would with the policy in the child, without torch; the
server batches every child of a policy into one pass; a child that writes nonsense, dies or
hangs loses its own slots and no other child's; a server that gives no answer fails the worker
in words."""

import contextlib
import multiprocessing
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from rl.learner import weights_bytes
from rl.policies import Policy
from rl.policy_lease import PolicyLease
from rl.policy_server import server_device
from rl.slots import ASK, REFUSED, SlotClient
from sandbox import MiB, Sandbox, SandboxFailure, served
from tests.helpers.sandbox import ENV, POLICY, REWARD, SEED, array, episodes_by_car
from tests.services import wait_for

CARS = 2
EPISODES = 2  # per car
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA on this machine")


@pytest.fixture
def socket_path() -> Iterator[str]:
    """A policy server's socket of the test's own; the server ends once its path is gone."""
    folder = Path(tempfile.mkdtemp(prefix="ps-"))
    yield str(folder / "policy.sock")
    for leftover in folder.iterdir():
        leftover.unlink()
    folder.rmdir()


@pytest.fixture(scope="module")
def other_weights(policy) -> bytes:
    """Another job's network: the same architecture, other weights."""
    other = Policy.for_environment(POLICY["algorithm"], POLICY["architecture"], ENV)
    return weights_bytes(other.weights_module.state_dict())


@contextlib.contextmanager
def started(weights: bytes, *, seed: int, lease: PolicyLease | None, job: int = 1):
    """A rollout's child of ``CARS`` cars seeded ``seed``, its policy in its slots of ``lease``'s
    server (None: held in the child), its reward function loaded and acting with ``weights``."""
    with Sandbox(
        env=ENV,
        cars=CARS,
        policy={**POLICY, "seed": seed, "job": job},
        policy_lease=lease,
        memory_allowance=1024 * MiB,
    ) as sandbox:
        sandbox.load(REWARD)
        sandbox.set_weights(1, weights)
        yield sandbox


def drives(sandbox: Sandbox) -> dict:
    """What ``sandbox``'s cars drive: ``EPISODES`` each, then one evaluation."""
    return {
        "episodes": episodes_by_car(sandbox, EPISODES),
        "evaluation": sandbox.episode("evaluate", start=1)["summary"],
    }


def torch_loaded(sandbox: Sandbox) -> bool:
    """Whether the child has torch's library mapped."""
    with open(f"/proc/{sandbox._process.pid}/maps") as maps:
        return "libtorch" in maps.read()


def assert_same_driving(got: dict, want: dict) -> None:
    assert got["evaluation"] == want["evaluation"]
    for car in range(CARS):
        for served_episode, held in zip(got["episodes"][car], want["episodes"][car], strict=True):
            assert served_episode["trace"] == held["trace"]  # every row: place, action, reward
            for name in ("actions", "rewards", "obs:FRONT_FACING_CAMERA"):
                assert served_episode["arrays"][name] == held["arrays"][name], name
            # The same network on the same rows, in batches of other sizes on other threads.
            for name in ("values", "log_probs"):
                close = np.allclose(array(served_episode, name), array(held, name), 1e-5, 1e-6)
                assert close, name


@pytest.mark.slow
def test_children_of_two_jobs_served_together_drive_what_each_would_hold_its_policy_without_torch(
    weights, other_weights, socket_path
):
    # Job 1 has two children (as two rollout workers), job 2 one, with other weights.
    children = {"job 1, first": (1, SEED, weights), "job 1, second": (1, SEED + CARS, weights)}
    children["job 2"] = (2, SEED, other_weights)  # the same seeds as job 1's first
    held = {}
    for name, (job, seed, given) in children.items():
        with started(given, seed=seed, lease=None, job=job) as sandbox:
            held[name] = drives(sandbox)
    served_drives, loaded, failures = {}, {}, []

    def drive(name: str) -> None:
        job, seed, given = children[name]
        try:
            with started(given, seed=seed, lease=PolicyLease(socket_path, "cpu"), job=job) as child:
                loaded[name] = torch_loaded(child)
                served_drives[name] = drives(child)
        except Exception as error:  # said by the test's thread below
            failures.append(error)

    threads = [threading.Thread(target=drive, args=(name,)) for name in children]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert failures == []
    assert loaded == dict.fromkeys(children, False)
    for name in children:
        assert_same_driving(served_drives[name], held[name])
    # Another network values the same first frame otherwise (untrained, both may pick the same
    # actions from the same seeds).
    first_of = {name: array(drove["episodes"][0][0], "values")[0] for name, drove in held.items()}
    assert first_of["job 2"] != first_of["job 1, first"]


PROBING = """import mmap

mapped = []
for fd in range(3, 256):  # whatever descriptor the child was handed, its slots' memory first
    try:
        mmap.mmap(fd, 4096)
        mapped.append(fd)
    except (OSError, ValueError):
        pass
print("mapped", mapped)


def reward_function(params):
    return 1.0
"""


@pytest.mark.slow
def test_the_racers_code_cannot_map_its_childs_slots_in_the_policy_server(socket_path):
    with Sandbox(
        env=ENV,
        policy={**POLICY, "seed": SEED, "job": 1},
        policy_lease=PolicyLease(socket_path, "cpu"),
        memory_allowance=1024 * MiB,
    ) as sandbox:
        sandbox.load(PROBING)
        # It mapped the slots' memory before the reward process closed what the child was handed
        assert sandbox.take_logs() == (["mapped []"], 0)


class Child:
    """A sandbox child as the server sees one, played by the test: its lease and its slots."""

    def __init__(self, socket_path: str, weights: bytes, *, job: int = 1, patience: float = 5.0):
        self.lease = PolicyLease(socket_path, "cpu")
        self.lease.open(
            job=job, algorithm=POLICY["algorithm"], architecture=POLICY["architecture"], env=ENV,
            seed=SEED, cars=CARS,
        )  # fmt: skip
        self.slots = SlotClient(self.lease.layout, *self.lease.fds, patience)
        self.ring = self.lease.fds[1]
        self.lease.fds = ()  # the test holds them, as a child would
        self.lease.weights(weights)

    def explore(self, frames: list[np.ndarray]) -> dict:
        observations = [{"FRONT_FACING_CAMERA": frame} for frame in frames]
        return self.slots.act("explore", observations, [SEED + car for car in range(len(frames))])

    def drive(self, frames: list[np.ndarray]) -> np.ndarray:
        """The deterministic actions, as a checkpoint's evaluation asks for its cars'."""
        observations = [{"FRONT_FACING_CAMERA": frame} for frame in frames]
        return self.slots.act("drive", observations, None)["actions"]

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.ring)
        self.lease.close()


def frames(count: int, fill: int) -> list[np.ndarray]:
    shape = (1, 120, 160)  # the camera's, channel first
    return [np.full(shape, fill + car, np.uint8) for car in range(count)]


def expected(policy: Policy, given: bytes, seen: list[np.ndarray]) -> tuple:
    policy.load_published(given)
    observations = [{"FRONT_FACING_CAMERA": frame} for frame in seen]
    return policy.explore(observations, [Policy.generator(SEED + car) for car in range(len(seen))])


@pytest.mark.slow
def test_two_jobs_children_are_answered_in_one_pass_each_and_never_with_the_others_policy(
    policy, weights, other_weights, socket_path
):
    first, second, other = (
        Child(socket_path, weights),
        Child(socket_path, weights),
        Child(socket_path, other_weights, job=2),
    )
    try:
        # All three ring while the server is stopped: it finds them together when it goes on.
        os.kill(first.lease.server_pid, signal.SIGSTOP)
        answers: dict[str, dict] = {}
        threads = [
            threading.Thread(target=lambda n=n, c=c, f=f: answers.update({n: c.explore(f)}))
            for n, c, f in (
                ("first", first, frames(2, 10)),
                ("second", second, frames(2, 50)),
                ("other", other, frames(2, 10)),
            )
        ]
        for thread in threads:
            thread.start()
        time.sleep(0.5)
        os.kill(first.lease.server_pid, signal.SIGCONT)
        for thread in threads:
            thread.join()
        stats = first.lease.stats()
    finally:
        os.kill(first.lease.server_pid, signal.SIGCONT)
        for child in (first, second, other):
            child.close()
    assert (stats["passes"], stats["most_rows"], stats["policies"]) == (2, 4, 2)
    for name, given, seen in (
        ("first", weights, frames(2, 10)),
        ("second", weights, frames(2, 50)),
        ("other", other_weights, frames(2, 10)),
    ):
        actions, values, log_probs = expected(policy, given, seen)
        assert np.array_equal(answers[name]["actions"], actions), name
        assert np.allclose(answers[name]["values"], values, rtol=1e-5, atol=1e-6), name
        assert np.allclose(answers[name]["log_probs"], log_probs, rtol=1e-5, atol=1e-6), name
    assert not np.array_equal(answers["first"]["values"], answers["other"]["values"])


@pytest.mark.slow
def test_an_evaluations_cars_ride_in_their_jobs_exploring_pass_and_drive_as_their_policy_would(
    policy, weights, socket_path
):
    # The server waits up to 1 s for the explorer to ask again (RIDE is 50 ms): under the whole
    # suite on 2 cores, the explorer's 20 ms between steps stretched past 50 ms for half its steps
    command = ["--socket", socket_path, "--device", "cpu", "--ride", "1", "--idle", "60"]
    listening = subprocess.Popen(
        [sys.executable, "-m", "rl.policy_server", *command], start_new_session=True
    )
    wait_for(lambda: os.path.exists(socket_path), "the policy server to listen", 60)
    explorer, evaluator = Child(socket_path, weights), Child(socket_path, weights)
    server = explorer.lease.server_pid
    assert server == listening.pid
    try:
        # Both ask while the server is stopped: one pass of 4 rows answers them.
        os.kill(server, signal.SIGSTOP)
        answers: dict[str, object] = {}
        asks = {
            "explored": (explorer.explore, frames(2, 10)),
            "driven": (evaluator.drive, frames(2, 90)),
        }
        threads = [
            threading.Thread(target=lambda n=n, ask=ask, f=f: answers.update({n: ask(f)}))
            for n, (ask, f) in asks.items()
        ]
        for thread in threads:
            thread.start()
        time.sleep(0.5)
        os.kill(server, signal.SIGCONT)
        for thread in threads:
            thread.join()
        together = explorer.lease.stats()

        # The evaluator asks without pause while the explorer's cars take 20 ms a step: it is
        # answered in the explorer's passes, once a step, not in passes of its own between them.
        steps, exploring, driven = 20, threading.Event(), [0]

        def evaluate() -> None:
            while exploring.is_set():
                evaluator.drive(frames(2, 90))
                driven[0] += 1

        exploring.set()
        riding = threading.Thread(target=evaluate)
        riding.start()
        for _ in range(steps):
            explorer.explore(frames(2, 10))
            time.sleep(0.02)
        exploring.clear()
        riding.join(5)  # its last ask: answered alone once the explorer has stopped asking
        after = explorer.lease.stats()
    finally:
        os.kill(server, signal.SIGCONT)
        explorer.close()
        evaluator.close()
        listening.terminate()
        listening.wait(10)
    assert (together["passes"], together["rows"]) == (1, 4)
    actions, values, _ = expected(policy, weights, frames(2, 10))
    assert np.array_equal(answers["explored"]["actions"], actions)
    assert np.allclose(answers["explored"]["values"], values, rtol=1e-5, atol=1e-6)
    policy.load_published(weights)
    driven_alone = policy.drive_rows([{"FRONT_FACING_CAMERA": f} for f in frames(2, 90)])
    assert np.array_equal(answers["driven"], driven_alone)
    assert not riding.is_alive()
    passes = after["passes"] - together["passes"]
    # one a step, and one for the evaluator's last ask; a stall of the machine past the 1 s
    # would let an ask go alone, hence the margin. Without riding, the evaluator is answered in
    # passes of its own between the explorer's, some five a step (99 passes with --ride 0)
    assert steps <= driven[0] <= passes <= steps + steps // 2, (driven[0], passes)
    assert after["rows"] - together["rows"] == 2 * steps + 2 * driven[0]


@pytest.mark.slow
def test_three_jobs_children_that_keep_asking_are_answered_in_turn_none_starved(
    weights, other_weights, socket_path
):
    children = [Child(socket_path, given, job=job) for job, given in enumerate(
        (weights, other_weights, weights), start=1
    )]  # fmt: skip
    forked = multiprocessing.get_context("fork")  # each child a process, as sandbox children are
    answered = [forked.Value("i", 0) for _ in children]
    enough = forked.Event()  # the first to have 90 answers ends the race
    ready, all_ready = forked.Value("i", 0), forked.Event()

    def keep_asking(place: int) -> None:
        # The race starts once every child has had its first answer: until then, the first
        # child's turns are not taken from the others but from their policies' loading (each
        # job's 47 MB of weights), which a busy machine may stretch over many rounds.
        children[place].explore(frames(2, place))
        with ready.get_lock():
            ready.value += 1
            if ready.value == len(children):
                all_ready.set()
        all_ready.wait(60)
        while not enough.is_set():
            children[place].explore(frames(2, place))
            answered[place].value += 1
            if answered[place].value >= 90:
                enough.set()

    processes = [forked.Process(target=keep_asking, args=(place,)) for place in range(3)]
    try:
        for process in processes:
            process.start()
        for process in processes:
            process.join(60)
        stats = children[0].lease.stats()
    finally:
        for child in children:
            child.close()
    counts = [count.value for count in answered]
    # Each is answered once a round while it asks; the machine's other work may hold one child
    # back a little (60, 48, 41 under the whole suite, counted from the first child's first
    # answer; 90, 64, 53 in one run), but none waits out every other round as without the
    # server's turns (60, 31, 31).
    assert min(counts) >= 2 * max(counts) // 3, counts
    assert stats["policies"] == 3


@pytest.mark.slow
def test_a_child_that_writes_nonsense_dies_or_hangs_loses_its_own_slots_and_no_one_elses(
    weights, socket_path
):
    bystander = Child(socket_path, weights)
    try:
        cases = {
            "it asked for something the policy does not do": (0, 7),
            "it asked for 5 rows of a policy serving 2": (1, 5),
            "it named cars that are not its own": (2, SEED + 9),
        }
        for reason, (field, value) in cases.items():
            liar = Child(socket_path, weights)
            try:
                header = liar.slots.views["header"]
                header[:] = [0, 1, SEED, SEED + 1]
                header[field] = value
                os.write(liar.ring, ASK)
                assert liar.slots.ready.poll(5000)
                words = f"The policy server refused the cars: {reason}."
                assert os.read(liar.ring, 4096) == REFUSED + words.encode()
                assert os.read(liar.ring, 16) == b""  # its socket closed: its slots are gone
            finally:
                liar.close()
            bystander.explore(frames(2, 0))  # still served
        dying = Child(socket_path, weights)
        os.write(dying.ring, ASK)
        dying.close()  # gone before the answer
        hanging = Child(socket_path, weights)
        os.write(hanging.ring, ASK)  # and never reads
        try:
            assert bystander.explore(frames(2, 0))["actions"].shape == (2,)
            assert bystander.lease.stats()["policies"] == 1
        finally:
            hanging.close()
    finally:
        bystander.close()


@pytest.mark.slow
def test_a_policy_server_that_gives_no_answer_fails_the_worker_in_words_rather_than_hang(
    weights, socket_path, monkeypatch
):
    from jobs.rollouts import failure_words

    monkeypatch.setattr(served, "CHILD_PATIENCE", 1.0)
    lease = PolicyLease(socket_path, "cpu")
    with started(weights, seed=SEED, lease=lease) as sandbox:
        os.kill(lease.server_pid, signal.SIGSTOP)
        try:
            with pytest.raises(SandboxFailure) as failed:
                sandbox.episode("explore", start=1)
        finally:
            os.kill(lease.server_pid, signal.SIGCONT)
    assert failed.value.kind == "policy"
    assert str(failed.value) == "The policy server gave no answer in 1 s."
    assert failure_words(failed.value, 1) == (
        "Simulation worker 2 failed (not your reward function): "
        "The policy server gave no answer in 1 s."
    )


def test_the_server_runs_on_the_gpu_where_torch_finds_one_and_a_gpu_asked_for_must_be_there(
    monkeypatch,
):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert server_device("auto") == "cpu"
    assert server_device("cpu") == "cpu"
    with pytest.raises(ValueError, match="PITLANE_ROLLOUT_DEVICE is cuda, but PyTorch finds no"):
        server_device("cuda")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert server_device("auto") == "cuda"


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a GPU")
def test_a_gpu_asked_for_where_there_is_none_fails_the_worker_in_words(socket_path):
    from jobs.rollouts import failure_words

    with pytest.raises(SandboxFailure) as failed, started(b"", seed=SEED, lease=PolicyLease(
        socket_path, "cuda"
    )):  # fmt: skip
        pass
    assert failed.value.kind == "policy"
    assert failure_words(failed.value, 0) == (
        "Simulation worker 1 failed (not your reward function): The policy server did not "
        "start: PITLANE_ROLLOUT_DEVICE is cuda, but PyTorch finds no GPU on this simulation "
        "machine: set it to auto or cpu, or give the machine a GPU PyTorch can use."
    )


def test_a_rollout_worker_has_its_sandboxes_served_unless_the_policy_is_kept_in_the_child(
    settings,
):
    from jobs.rollouts import _sandboxes, cars_for

    model = SimpleNamespace(
        algorithm="clipped_ppo",
        architecture=POLICY["architecture"],
        seed=3,
        environment_settings=lambda track: {"track": track},
    )
    for device, served_by in (("auto", True), ("cuda", True), ("child", False)):
        settings.PITLANE_ROLLOUT_DEVICE = device
        sandbox = _sandboxes(model, 12, 1, "pitlane-oval")(2)  # made, not started
        assert (sandbox.policy_lease is not None, sandbox.cars) == (served_by, 2)
        if served_by:
            assert sandbox.policy_lease.device == device
        assert sandbox.policy["seed"] == 3 + cars_for("clipped_ppo")  # after worker 0's cars
        assert sandbox.policy["job"] == 12


@needs_cuda
def test_a_child_whose_policy_is_served_from_the_gpu_drives_its_cars(weights, socket_path):
    lease = PolicyLease(socket_path, "cuda")
    with started(weights, seed=SEED, lease=lease) as sandbox:
        assert lease.served_on.startswith("cuda")
        assert not torch_loaded(sandbox)
        driven = drives(sandbox)
    assert all(len(episodes) == EPISODES for episodes in driven["episodes"].values())
    assert driven["evaluation"]["steps"] > 0


@needs_cuda
@pytest.mark.django_db(transaction=True)
def test_a_job_on_a_machine_with_a_gpu_learns_and_serves_its_cars_on_it(
    alice, tracks, celery_worker_process
):
    from tests.helpers.training import settings, wait_for_job
    from training.models import TrainingJob
    from training.services import model_create, training_stop

    job = model_create(owner=alice, settings=settings()).jobs.get()
    job = wait_for_job(job, lambda j: j.iterations >= 1, "a policy update")
    lines = list(job.log_lines.values_list("text", flat=True))
    assert any(
        line.startswith("Training started") and "learning on the GPU" in line for line in lines
    ), lines
    assert any("served by the machine's policy server on the GPU" in line for line in lines), lines
    training_stop(job=job)
    wait_for_job(job, lambda j: j.status == TrainingJob.Status.COMPLETED, "the stop", 120)
