"""A policy served to the sandbox child by its worker (``Sandbox(policy_device=...)``,
``sandbox.served``), as a rollout worker does where it infers on the GPU: the child, which never
loads torch, drives the same episodes as one holding the policy; the worker's time over the
policy is never counted against the reward function; a policy that fails or gives no answer
fails the worker in words; and a request for the policy out of protocol is refused."""

import contextlib
import time
import zlib
from collections.abc import Iterator
from types import SimpleNamespace

import msgpack
import numpy as np
import pytest
import torch

import sandbox as sandbox_package
from rl.experience import decode_array, encode_arrays
from rl.policies import Policy, rollout_device
from rl.wire import ProtocolError
from sandbox import MiB, Sandbox, SandboxFailure, served
from sandbox.served import PolicyServer
from tests.helpers.sandbox import ENV, POLICY, REWARD, SEED, array, episodes_by_car

CARS = 2
EPISODES = 2  # per car
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA on this machine")


@contextlib.contextmanager
def started(weights: bytes, *, cars: int = 1, device: str | None) -> Iterator[Sandbox]:
    """A rollout's child of ``cars`` cars seeded ``SEED``, its policy served from ``device``
    (None: held in the child), its reward function loaded and acting with ``weights``."""
    with Sandbox(
        env=ENV,
        cars=cars,
        policy={**POLICY, "seed": SEED},
        policy_device=device,
        memory_allowance=1024 * MiB,
    ) as sandbox:
        sandbox.load(REWARD)
        sandbox.set_weights(1, weights)
        yield sandbox


def torch_loaded(sandbox: Sandbox) -> bool:
    """Whether the child has torch's library mapped."""
    with open(f"/proc/{sandbox._process.pid}/maps") as maps:
        return "libtorch" in maps.read()


@pytest.mark.slow
def test_a_child_whose_policy_is_served_drives_the_episodes_one_holding_it_would_without_torch(
    weights,
):
    driven, evaluated, loaded = {}, {}, {}
    for device in (None, "cpu"):
        with started(weights, cars=CARS, device=device) as sandbox:
            loaded[device] = torch_loaded(sandbox)
            driven[device] = episodes_by_car(sandbox, EPISODES)
            evaluated[device] = sandbox.episode("evaluate", start=1)["summary"]  # as Evaluator
    assert loaded == {None: True, "cpu": False}
    assert evaluated["cpu"] == evaluated[None]
    for car in range(CARS):
        for got, want in zip(driven["cpu"][car], driven[None][car], strict=True):
            assert got["trace"] == want["trace"]  # every row: place, action, reward, status
            for name in ("actions", "rewards", "obs:FRONT_FACING_CAMERA"):
                assert got["arrays"][name] == want["arrays"][name], name
            # The same network on the same rows, though on this process's threads there.
            for name in ("values", "log_probs"):
                assert np.allclose(array(got, name), array(want, name), rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_the_time_the_worker_takes_over_the_policy_is_not_counted_against_the_reward_function(
    weights, monkeypatch
):
    # The worker kills a child silent for a call's limit and the grace (1.5 s here); its own
    # policy taking longer than that over a step is not the child's silence.
    monkeypatch.setattr(sandbox_package, "GRACE", 0.5)
    answered = PolicyServer._run
    slow = iter([2.0])

    def slow_run(self, *args):
        time.sleep(next(slow, 0.0))
        return answered(self, *args)

    monkeypatch.setattr(PolicyServer, "_run", slow_run)
    with started(weights, device="cpu") as sandbox:
        reply = sandbox.episode("explore", start=1)
    assert msgpack.unpackb(reply["payload"])["steps"] > 1


@pytest.mark.slow
def test_a_policy_that_gives_no_answer_fails_the_worker_in_words_rather_than_hang(
    weights, monkeypatch
):
    from jobs.rollouts import failure_words

    monkeypatch.setattr(served, "ANSWER_TIMEOUT", 0.5)
    monkeypatch.setattr(PolicyServer, "_run", lambda self, *args: time.sleep(3.0))
    with started(weights, device="cpu") as sandbox, pytest.raises(SandboxFailure) as failed:
        sandbox.episode("explore", start=1)
    assert failed.value.kind == "policy"
    assert str(failed.value) == "The policy on the CPU gave no answer in 0.5 s."
    assert failure_words(failed.value, 1) == (
        "Simulation worker 2 failed (not your reward function): "
        "The policy on the CPU gave no answer in 0.5 s."
    )


@pytest.mark.slow
def test_a_child_left_without_an_answer_gives_up_and_says_so_rather_than_wait_for_ever(
    weights, monkeypatch
):
    # The worker stalls past the child's patience (elsewhere than over the policy, which has a
    # limit of its own): the child ends, and the worker reads why.
    monkeypatch.setattr(served, "CHILD_PATIENCE", 0.5)
    answered = PolicyServer.answer
    monkeypatch.setattr(
        PolicyServer, "answer", lambda self, request: time.sleep(2.0) or answered(self, request)
    )
    with started(weights, device="cpu") as sandbox, pytest.raises(SandboxFailure) as failed:
        sandbox.episode("explore", start=1)
    assert failed.value.kind == "policy"
    assert str(failed.value) == "The worker did not answer with the cars' actions."


def pack_array(array: np.ndarray) -> dict:
    """An array as a child's request carries it (uncompressed, over a pipe)."""
    return encode_arrays({"array": array}, compress=False)["array"]


def request(policy: Policy, cars: int, how: str = "explore", **changes) -> dict:
    """A child's request for the policy's answer for ``cars`` cars seeded ``SEED`` on."""
    spaces = policy.network.observation_space.spaces
    observations = {
        name: pack_array(np.zeros((cars, *space.shape), space.dtype))
        for name, space in spaces.items()
    }
    seeds = [SEED + car for car in range(cars)] if how == "explore" else None
    return {"type": "act", "how": how, "observations": observations, "seeds": seeds, **changes}


def test_the_worker_answers_each_car_from_its_own_stream_as_the_policy_would(policy):
    server = PolicyServer(policy, SEED, cars=3)
    space = policy.network.observation_space["FRONT_FACING_CAMERA"]
    observations = [{"FRONT_FACING_CAMERA": np.zeros(space.shape, np.uint8)}] * 2
    generators = [Policy.generator(SEED + 2), Policy.generator(SEED)]
    expected = policy.explore(observations, generators)
    try:
        answer = server.answer(request(policy, 2, seeds=[SEED + 2, SEED]))["arrays"]
        value = server.answer(request(policy, 1, "value"))["arrays"]["values"]
    finally:
        server.close()
    for name, want in zip(("actions", "values", "log_probs"), expected, strict=True):
        got = np.frombuffer(answer[name]["data"], dtype=answer[name]["dtype"])
        assert np.array_equal(got, want), name
    assert np.frombuffer(value["data"], "float32")[0] == pytest.approx(
        policy.value(observations[0]), rel=1e-6
    )


@pytest.mark.parametrize(
    ("cars", "changes", "how"),
    [
        (2, {"seeds": [SEED, SEED + 5]}, "explore"),  # a car the child does not drive
        (2, {"seeds": [SEED, SEED]}, "explore"),  # one car's stream twice
        (2, {"seeds": [SEED, [SEED]]}, "explore"),
        (4, {}, "explore"),  # more cars than it drives
        (2, {}, "drive"),  # evaluations drive one car
        (1, {}, "train"),
        (1, {"observations": {}}, "explore"),
    ],
)
def test_a_request_for_the_policy_out_of_protocol_is_refused(policy, cars, changes, how):
    server = PolicyServer(policy, SEED, cars=3)
    try:
        with pytest.raises(ProtocolError):
            server.answer(request(policy, cars, how, **changes))
    finally:
        server.close()


def test_an_observation_of_another_kind_is_refused_before_the_network_sees_it(policy):
    server = PolicyServer(policy, SEED, cars=3)
    shape = (1, *policy.network.observation_space["FRONT_FACING_CAMERA"].shape)
    cases = [
        ("expected uint8", pack_array(np.zeros(shape, np.float64))),
        ("expected shape", pack_array(np.zeros((1, 3, 4), np.uint8))),
        ("expected shape", {**pack_array(np.zeros(shape, np.uint8)), "shape": [2**70, *shape[1:]]}),
        ("bytes do not match", {**pack_array(np.zeros(shape, np.uint8)), "data": b"\0" * 10}),
    ]
    try:
        for message, packed in cases:
            with pytest.raises(ProtocolError, match=message):
                server.answer(request(policy, 1, observations={"FRONT_FACING_CAMERA": packed}))
    finally:
        server.close()


@pytest.mark.parametrize("compressed", [False, True], ids=["served", "experience"])
def test_an_array_is_held_to_its_shape_served_or_from_the_experience_buffer(compressed):
    # One decoder for both: each size a whole number under 2**31, exactly its shape's bytes.
    def encoded(array: np.ndarray, **changes) -> dict:
        return {**encode_arrays({"a": array}, compress=compressed)["a"], **changes}

    frames = np.arange(24, dtype=np.uint8).reshape(2, 3, 4)
    decoded = decode_array(encoded(frames), "uint8", (None, 3, 4), compressed=compressed)
    assert np.array_equal(decoded, frames)
    inflating = zlib.compress(bytes(1 << 20)) if compressed else bytes(1 << 20)  # 1 MB for 24 B
    cases = [
        ("expected shape", encoded(frames, shape=[2.0, 3, 4])),
        ("expected shape", encoded(frames, shape=[2**31, 3, 4])),
        ("do not match its shape", encoded(frames, data=inflating)),
        ("do not match its shape", encoded(frames[:1], shape=[2, 3, 4])),
    ]
    for message, case in cases:
        with pytest.raises(ProtocolError, match=message):
            decode_array(case, "uint8", (None, 3, 4), compressed=compressed)


def test_a_sensor_reading_that_is_not_a_finite_number_is_refused_before_the_network_sees_it():
    import gymnasium

    ran = []
    lidar = gymnasium.spaces.Box(0.0, 1.0, (8,), np.float32)
    stand_in = SimpleNamespace(  # a policy on a lidar's readings, which counts what it runs
        network=SimpleNamespace(observation_space=gymnasium.spaces.Dict({"LIDAR": lidar})),
        generator=Policy.generator,
        explore=lambda *args: ran.append(args),
    )
    server = PolicyServer(stand_in, SEED, cars=1)
    ran.clear()  # its run once, made ready
    readings = np.full((1, 8), 0.5, np.float32)
    readings[0, 3] = np.nan
    try:
        with pytest.raises(ProtocolError, match="not finite"):
            server.answer(
                {"how": "explore", "seeds": [SEED], "observations": {"LIDAR": pack_array(readings)}}
            )
    finally:
        server.close()
    assert ran == []


def test_the_rollout_device_is_the_gpu_where_torch_finds_one_and_a_gpu_asked_for_must_be_there(
    monkeypatch,
):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert rollout_device("auto") == "cpu"
    assert rollout_device("cpu") == "cpu"
    with pytest.raises(ValueError, match="PITLANE_ROLLOUT_DEVICE is cuda, but PyTorch finds no"):
        rollout_device("cuda")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert rollout_device("auto") == "cuda"


def test_a_rollout_worker_serves_its_sandboxes_the_policy_where_it_runs_off_the_cpu():
    from jobs.rollouts import _sandboxes, cars_for

    model = SimpleNamespace(
        algorithm="clipped_ppo",
        architecture=POLICY["architecture"],
        seed=3,
        environment_settings=lambda track: {"track": track},
    )
    for device, served_from in (("cuda", "cuda"), ("cpu", None)):
        sandbox = _sandboxes(model, 1, "pitlane-oval", device)(2)  # made, not started
        assert (sandbox.policy_device, sandbox.cars) == (served_from, 2)
        assert sandbox.policy["seed"] == 3 + cars_for("clipped_ppo")  # after worker 0's cars


@needs_cuda
def test_a_child_whose_policy_is_served_from_the_gpu_drives_its_cars(weights):
    with started(weights, cars=CARS, device="cuda") as sandbox:
        assert sandbox.server.device.startswith("cuda")
        assert not torch_loaded(sandbox)
        driven = episodes_by_car(sandbox, 1)
        evaluated = sandbox.episode("evaluate", start=1)["summary"]
    assert all(len(episodes) == 1 and episodes[0]["steps"] > 0 for episodes in driven.values())
    assert evaluated["steps"] > 0


@needs_cuda
@pytest.mark.django_db(transaction=True)
def test_a_job_on_a_machine_with_a_gpu_learns_on_it_and_its_cars_drive_on_the_cpu(
    alice, tracks, celery_worker_process
):
    """PITLANE_ROLLOUT_DEVICE's default, cpu, on a GPU machine too (console/settings/base.py says
    why); a child served from the GPU drives in the test above."""
    from tests.helpers.training import settings, wait_for_job
    from training.models import TrainingJob
    from training.services import model_create, training_stop

    job = model_create(owner=alice, settings=settings()).jobs.get()
    job = wait_for_job(job, lambda j: j.iterations >= 1, "a policy update")
    lines = list(job.log_lines.values_list("text", flat=True))
    assert any(
        line.startswith("Training started") and "learning on the GPU" in line for line in lines
    ), lines
    driving = [line for line in lines if "is driving" in line]
    assert driving and not any("policy on the GPU" in line for line in driving), lines
    training_stop(job=job)
    wait_for_job(job, lambda j: j.status == TrainingJob.Status.COMPLETED, "the stop", 120)
