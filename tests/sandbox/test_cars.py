"""A rollout's child that drives several cars together (``Sandbox(cars=...)``,
``rl.episode.Fleet``): each car drives the episodes a child of one car would, step for step, the
reward process is asked once a step for all the cars, and a reward function that fails in one car
fails with its reason, as it does where one car drives."""

import contextlib
import functools
from collections.abc import Iterator

import gymnasium
import numpy as np
import pytest

import sandbox as sandbox_package
import simulator
from rl.episode import Fleet
from rl.policies import Policy
from sandbox import MiB, Sandbox, SandboxFailure
from sandbox.reward import RewardProcess
from simulator.trace import FIELDS
from tests.helpers.sandbox import (
    ENV,
    POLICY,
    REWARD,
    SEED,
    array,
    assert_stopped,
    episodes_by_car,
    outcome,
    reward,
)

CARS = 2
EPISODES = 2  # per car


@contextlib.contextmanager
def child(
    weights: bytes,
    *,
    cars: int,
    seed: int,
    start: float = 0.0,
    in_turn: bool = False,
    source: str = REWARD,
) -> Iterator[Sandbox]:
    """A rollout's child of ``cars`` cars, ready to drive: its reward function (``source``)
    loaded, and acting with ``weights``."""
    env = {**ENV, "start": start} if start else ENV
    with Sandbox(
        env=env,
        cars=cars,
        in_turn=in_turn,
        policy={**POLICY, "seed": seed},
        memory_allowance=1024 * MiB,
    ) as sandbox:
        sandbox.load(source)
        sandbox.set_weights(1, weights)
        yield sandbox


@pytest.mark.slow
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
                want["steps"],
                want["status"],
                want["progress"],
            )
            for name in ("actions", "rewards", "obs:FRONT_FACING_CAMERA"):
                assert got["arrays"][name] == want["arrays"][name], name
            # The critic's value and the action's log-probability come from a batch of two
            # rows here and of one there: the same numbers, but a matrix product's sums may be
            # grouped otherwise, so they may differ in the last bits of a float32.
            for name in ("values", "log_probs"):
                assert np.allclose(array(got, name), array(want, name), rtol=1e-5, atol=1e-6)
    starts = [episodes[0]["trace"][0][2:4] for episodes in driven.values()]
    assert starts[0] != starts[1]  # the cars drove from places of their own


def evaluated(sandbox: Sandbox, rounds: int) -> list[dict]:
    """The summaries of ``rounds`` evaluations of a car each, as a checkpoint's are driven
    (``jobs.rollouts.CheckpointEvaluator``): every car starts one, and the results come as they
    end; in the order of the cars, round by round."""
    summaries = []
    for _ in range(rounds):
        ended = {}
        for place in range(sandbox.cars):
            reply = sandbox.episode("evaluate", start=sandbox.cars if place == 0 else 0)
            ended[reply["car"]] = {k: v for k, v in reply["summary"].items() if k != "car"}
        summaries += [ended[car] for car in range(sandbox.cars)]
    return summaries


@pytest.mark.slow
def test_cars_evaluating_in_turn_drive_the_episodes_one_car_drives_one_after_another(weights):
    # Car k's j-th episode starts where one car's ((j - 1) * cars + k + 1)-th does: 5% of the
    # lap apart, in order, over two evaluations. Without ``in_turn``, a third of the lap apart.
    # REWARD without its count of calls, which one car's copy would carry from one to the next.
    source = reward("return params['progress'] + params['speed'] + abs(params['heading']) / 100")
    with child(weights, cars=3, seed=SEED, in_turn=True, source=source) as together:
        driven = evaluated(together, rounds=2)
    with child(weights, cars=1, seed=SEED, source=source) as alone:
        expected = evaluated(alone, rounds=6)
    # the same places but for the last bits: a start of (k + 1 - cars) * 5% plus cars * 5% an
    # episode, not 5% an episode
    assert driven == [pytest.approx(each, rel=1e-9) for each in expected]
    assert len({(each["steps"], each["progress"]) for each in expected}) > 1  # starts differ


STATUS = FIELDS.index("episode_status")  # a trace row's


def fleet_driven(policy: Policy, *, together: bool) -> tuple[list, int, int]:
    """Four cars' evaluation episodes, driven at random, their rewards from a reward process
    of their own: asked for all four in one call a step (``together``), or by each car's
    environment in turn. (Each car's episode, the fleet's steps, the process's round trips.)"""
    cars = 4
    process = RewardProcess(1.0, 1024 * MiB)
    try:
        process.wait_ready(60.0)
        process.load(REWARD, copies=cars)
        # Penalties leave the car still, its steps paused without a reward call; the third
        # time off the track ends the episode.
        envs = [
            gymnasium.make(
                simulator.ENV_ID,
                **ENV,
                mode="evaluation",
                max_resets=2,
                start=car / cars,
                reward_fn=functools.partial(process.call, car=car),
            )
            for car in range(cars)
        ]
        score = process.calls if together else None
        fleet = Fleet(envs, policy, [SEED + car for car in range(cars)], score=score)
        for car in fleet.cars:
            fleet.start(car, "random", seed=SEED)
        asked, steps = process.round_trips, 0
        while fleet.driving():
            fleet.step()
            steps += 1
        return [car.driven for car in fleet.cars], steps, process.round_trips - asked
    finally:
        process.stop()


@pytest.mark.slow
def test_a_fleet_asks_the_reward_process_once_a_step_for_all_its_cars_and_drives_the_same_episodes(
    policy,
):
    one_by_one, _, asked_by_each = fleet_driven(policy, together=False)
    together, steps, asked_together = fleet_driven(policy, together=True)
    statuses = [row[STATUS] for driven in one_by_one for row in driven.trace[1:]]
    calls, paused = len(statuses) - statuses.count("pause"), statuses.count("pause")
    assert paused > 0  # steps that call no reward function were among them
    assert asked_by_each == calls + 1  # each call a round trip, and the waypoints once
    # A round trip a step (but for those where every car driving is paused), and the waypoints
    # once. Each car's trace has a row per step of the fleet's, the reset's first.
    scored = sum(
        any(
            len(driven.trace) > step and driven.trace[step][STATUS] != "pause"
            for driven in together
        )
        for step in range(1, steps + 1)
    )
    assert asked_together == scored + 1
    for alone, beside in zip(one_by_one, together, strict=True):
        assert beside.trace == alone.trace  # every row: place, action, reward, status
        assert beside.rewards == alone.rewards
        for name, frames in alone.observations.items():
            assert np.array_equal(np.stack(beside.observations[name]), np.stack(frames))


# Car k of n, which starts k / n of the lap on, alone meets this at its third step: the calls
# of the cars before it in the step's batch have returned.
ONE_CAR_ONLY = """\
share = params['closest_waypoints'][0] / len(params['waypoints'])
if params['steps'] == 3 and abs(share - {car} / {cars}) < 0.1:
{failing}
return 1.0
"""


@pytest.mark.slow
@pytest.mark.parametrize(
    ("cars", "car", "failing", "kind", "message", "named"),
    [
        (3, 1, "    return {}['missing']", "exception", "line 4: KeyError", 1),
        (4, 3, "    while True: pass", "timeout",
         "line 4: The reward function took longer than 1 s", 3),
        (4, 2, "    x = bytearray(2 * 1024 ** 3)", "memory",
         "line 4: The reward function ran out of memory", 2),
        # An alarm ignored: the car's call stopped by its own deadline, its car named.
        (2, 1, "    __import__('signal').signal(14, lambda *_: None)\n    while True: pass",
         "timeout", "The reward function took longer than 1 s; it was stopped", 1),
    ],
    ids=["exception", "timeout", "memory", "ignored-alarm"],
)  # fmt: skip
def test_a_reward_function_that_fails_in_one_of_several_cars_fails_with_its_reason(
    weights, cars, car, failing, kind, message, named
):
    source = reward(ONE_CAR_ONLY.format(car=car, cars=cars, failing=failing))
    with Sandbox(env=ENV, cars=cars, policy=POLICY, memory_allowance=1024 * MiB) as sandbox:
        sandbox.load(source)
        sandbox.set_weights(1, weights)
        with pytest.raises(SandboxFailure) as failed:
            for _ in range(cars):  # the car fails at its third step, before any episode ends
                sandbox.episode("explore", start=cars)
    failure = failed.value
    assert (failure.kind, failure.car) == (kind, named)
    assert message in str(failure)
    assert (failure.step, failure.status) == (3, "in_progress")


@pytest.mark.slow
def test_a_step_of_four_cars_each_call_near_its_limit_is_not_late(weights, monkeypatch):
    # One request a step for the four cars' calls, each 0.4 s under a limit of 0.5 s: the
    # worker waits for a whole step (at the first and the second), not for one call.
    monkeypatch.setattr(sandbox_package, "GRACE", 0.5)  # 1 s a step would once have been late
    slow = "import time\n" + reward("if params['steps'] <= 2:\n    time.sleep(0.4)\nreturn 1.0")
    with Sandbox(
        env=ENV, cars=4, policy=POLICY, call_timeout=0.5, memory_allowance=1024 * MiB
    ) as sandbox:
        sandbox.load(slow)
        sandbox.set_weights(1, weights)
        assert sandbox.episode("random", start=4)["summary"]["steps"] > 2


def test_the_racers_code_gets_the_same_memory_however_many_cars_its_worker_drives():
    # The child may map more per car (car_memory); the reward process, where the racer's code
    # runs, is held to memory_allowance with three cars as with one.
    hungry = reward("x = bytearray(600 * 1024 ** 2)\nreturn 1.0")
    for cars in (1, 3):
        result = outcome(hungry, cars=cars, memory_allowance=256 * MiB, car_memory=512 * MiB)
        assert_stopped(result, "memory", "ran out of memory")


@pytest.mark.slow
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


@pytest.mark.slow
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
