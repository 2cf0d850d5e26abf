"""A rollout's child that drives several cars together (``Sandbox(cars=...)``,
``rl.episode.Fleet``): each car drives the episodes a child of one car would, step for step, and a
reward function that fails in one car fails with its reason, as it does where one car drives."""

import contextlib
from collections.abc import Iterator

import msgpack
import numpy as np
import pytest

import sandbox as sandbox_package
from rl.learner import weights_bytes
from rl.policies import Policy
from sandbox import MiB, Sandbox, SandboxFailure
from tests.sandbox.test_sandbox import POLICY, assert_stopped, outcome, reward

ENV = {"track": "pitlane-oval"}
SEED = 7
CARS = 2
EPISODES = 2  # per car
# Reading where the car is and how it moves, so that any difference shows; and counting its
# calls in a global, as DeepRacer reward functions that remember the step before do: each car's
# calls must reach a copy of their own, or the cars' counts would mix.
REWARD = """calls = 0

def reward_function(params):
    global calls
    calls += 1
    return params["progress"] + params["speed"] + abs(params["heading"]) / 100 + calls / 1000
"""


@pytest.fixture(scope="module")
def weights() -> bytes:
    """One network for every child: each would otherwise draw its own initial weights."""
    policy = Policy.for_environment(POLICY["algorithm"], POLICY["architecture"], ENV)
    return weights_bytes(policy.weights_module.state_dict())


@contextlib.contextmanager
def child(weights: bytes, *, cars: int, seed: int, start: float = 0.0) -> Iterator[Sandbox]:
    """A rollout's child of ``cars`` cars, ready to drive: its reward function loaded, and
    acting with ``weights``."""
    env = {**ENV, "start": start} if start else ENV
    with Sandbox(env=env, cars=cars, policy={**POLICY, "seed": seed},
                 memory_allowance=1024 * MiB) as sandbox:  # fmt: skip
        sandbox.load(REWARD)
        sandbox.set_weights(1, weights)
        yield sandbox


def episodes_by_car(sandbox: Sandbox, per_car: int) -> dict[int, list[dict]]:
    """Each car's first ``per_car`` episodes, driven as a rollout worker asks for them: every
    idle car starts one while more are wanted."""
    driven: dict[int, list[dict]] = {car: [] for car in range(sandbox.cars)}
    started = driving = 0
    while started < per_car * sandbox.cars or driving:
        start = min(sandbox.cars - driving, per_car * sandbox.cars - started)
        reply = sandbox.episode("explore", start=start)
        started += start
        driving = reply["driving"]
        driven[reply["car"]].append(msgpack.unpackb(reply["payload"]))
    return driven


def test_each_of_several_cars_drives_the_episodes_a_child_of_one_car_would(weights):
    with child(weights, cars=CARS, seed=SEED) as together:
        driven = episodes_by_car(together, EPISODES)
    for car in range(CARS):
        # Car k is seeded with the child's seed + k, and starts k / cars of the lap further on.
        with child(weights, cars=1, seed=SEED + car, start=car / CARS) as alone:
            expected = episodes_by_car(alone, EPISODES)[0]
        assert len(driven[car]) == len(expected) == EPISODES
        for got, want in zip(driven[car], expected, strict=True):
            assert got["trace"] == want["trace"]  # every row: place, action, reward, status
            assert (got["steps"], got["status"], got["progress"]) == (
                want["steps"], want["status"], want["progress"])  # fmt: skip
            for name in ("actions", "rewards", "obs:FRONT_FACING_CAMERA"):
                assert got["arrays"][name] == want["arrays"][name], name
            # The critic's value and the action's log-probability come from a batch of two
            # rows here and of one there: the same numbers, but a matrix product's sums may be
            # grouped otherwise, so they may differ in the last bits of a float32.
            for name in ("values", "log_probs"):
                assert np.allclose(array(got, name), array(want, name), rtol=1e-5, atol=1e-6)
    starts = [episodes[0]["trace"][0][2:4] for episodes in driven.values()]
    assert starts[0] != starts[1]  # the cars drove from places of their own


def array(payload: dict, name: str) -> np.ndarray:
    from rl.experience import decode_array

    return decode_array(payload["arrays"][name], "float32", (None,))


# The car that starts a third of the lap on (car 1 of 3) alone meets this, at its third step.
CAR_1_ONLY = """\
third = len(params['waypoints']) / 3
if params['steps'] == 3 and third < params['closest_waypoints'][0] < 2 * third:
{}
return 1.0
"""


@pytest.mark.parametrize(
    ("failing", "kind", "message"),
    [
        ("    return {}['missing']", "exception", "at step 3 (in_progress), line 4: KeyError"),
        (
            "    while True: pass",
            "timeout",
            "at step 3 (in_progress), line 4: The reward function took longer than 1 s",
        ),
    ],
)
def test_a_reward_function_that_fails_in_one_of_several_cars_fails_with_its_reason(
    weights, failing, kind, message
):
    with Sandbox(env=ENV, cars=3, policy=POLICY, memory_allowance=1024 * MiB) as sandbox:
        sandbox.load(reward(CAR_1_ONLY.format(failing)))
        sandbox.set_weights(1, weights)
        with pytest.raises(SandboxFailure) as failed:
            for _ in range(3):  # car 1 fails at its third step, before any car's episode ends
                sandbox.episode("explore", start=3)
    failure = failed.value
    assert (failure.kind, failure.car) == (kind, 1)
    assert message in str(failure)


def test_the_racers_code_gets_the_same_memory_however_many_cars_its_worker_drives():
    # The child may map more per car (car_memory); the reward process, where the racer's code
    # runs, is held to memory_allowance with three cars as with one.
    hungry = reward("x = bytearray(600 * 1024 ** 2)\nreturn 1.0")
    for cars in (1, 3):
        result = outcome(hungry, cars=cars, memory_allowance=256 * MiB, car_memory=512 * MiB)
        assert_stopped(result, "memory", "ran out of memory")


def test_a_module_whose_top_level_takes_most_of_the_call_limit_loads_for_three_cars(monkeypatch):
    # Each car's copy of the module runs within the call's limit (1 s); the worker waits for
    # the three, not for one (a grace shortened here to keep the test short).
    monkeypatch.setattr(sandbox_package, "GRACE", 0.5)
    slow = "import time\ntime.sleep(0.6)\n" + reward("return 1.0")
    with Sandbox(env=ENV, cars=3, call_timeout=1.0) as sandbox:
        sandbox.load(slow)


@pytest.mark.parametrize(
    ("reply", "message"),
    [
        ({"car": 0, "driving": 1}, "without its experience"),  # no payload
        ({"car": 0, "driving": 1, "payload": "text"}, "without its experience"),
        ({"car": 0, "driving": 0, "payload": b""}, "lost count"),  # 2 started, 1 sent: 1 drives
        ({"car": 2, "driving": 1, "payload": b""}, "no car it drives"),
    ],
)
def test_an_episode_the_child_sends_out_of_protocol_is_a_protocol_failure(reply, message):
    sandbox = Sandbox(cars=2)  # never started: its answer is the one given here
    sandbox._request = lambda *args: {"type": "episode", "summary": {}, **reply}
    with pytest.raises(SandboxFailure) as failed:
        sandbox.episode("explore", start=2)
    assert failed.value.kind == "protocol"
    assert message in str(failed.value)


def test_the_live_view_shows_the_lowest_numbered_car_that_drives_with_the_workers_episode():
    frames: list[dict] = []
    policy = {**POLICY, "seed": SEED}
    with Sandbox(env=ENV, cars=2, policy=policy, memory_allowance=1024 * MiB) as sandbox:
        # A step of 5 ms at least: car 1's last 78 steps alone span several frames (15 a second).
        sandbox.load("import time\n" + reward("time.sleep(0.005)\nreturn 1.0"))
        sandbox.on_frame = frames.append
        sandbox.watch({"spectator"})
        assert sandbox.episode("random", start=2)["car"] == 0  # with this seed, car 0 ends first
        frames.clear()
        assert sandbox.episode("random", start=0)["car"] == 1  # car 1 drives on alone
    # Car 1's frames, numbered as the worker's second episode, not car 0's standing still.
    assert frames
    assert {frame["episode"] for frame in frames} == {2}
