"""The hostile suite, second part: racers' code that plays the protocol rather than the
kernel. It forges frames, ignores its alarm, floods standard error, breaks off a frame, outlives
its worker. Each test asserts the bound that holds: the call ends by its deadline, the worker's
memory stays put, nothing outlives the worker, and the racer reads why."""

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator

import pytest

import sandbox as sandbox_package
from sandbox import GRACE, STDERR_KEEP, MiB, Sandbox, SandboxFailure
from sandbox.protocol import HEADER, Late, pack, read_frame_by, write_by
from sandbox.reward import KILL_GRACE, RewardFailure, RewardProcess
from tests.helpers.sandbox import alive, children_of
from training.rewards import reward_validate, static_problems

PARAMS = {"x": 1.0, "y": 2.0, "track_width": 0.76, "distance_from_center": 0.1}
LIMIT = 0.5  # [s] the reward function's time limit in these tests
DEADLINE = LIMIT + GRACE  # [s] the most a call may hold the worker
SLACK = 1.5  # [s] for a machine busy with other tests

# Code that finds every descriptor it may write to and writes ``DATA`` there: the worker's
# protocol pipe, if the reward function could reach it, is among them.
WRITE_EVERYWHERE = """
import os, signal
def everywhere(data):
    for fd in range(0, 64):
        try:
            os.write(fd, data)
        except OSError:
            pass
"""


def reward(body: str, head: str = "") -> str:
    return head + "def reward_function(params):\n" + textwrap.indent(textwrap.dedent(body), "    ")


def timed(source: str, params: dict = PARAMS, **settings) -> tuple[float | SandboxFailure, float]:
    """(what a call of ``source`` comes to, the seconds the call took)."""
    with Sandbox(call_timeout=LIMIT, **settings) as sandbox:
        try:
            sandbox.load(source)
        except SandboxFailure as failure:
            return failure, 0.0
        started = time.monotonic()
        try:
            result = sandbox.call(params)
        except SandboxFailure as failure:
            result = failure
        return result, time.monotonic() - started


def rss() -> int:
    """[bytes] this process's resident memory."""
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS"))


def forged(message: dict) -> str:
    return repr(pack(message))


@pytest.mark.slow
@pytest.mark.parametrize(
    ("before", "during", "kind"),
    [
        ("pass", "pass", "timeout"),
        # A reply header promising more than it sends.
        (f"everywhere({HEADER.pack(1000)!r} + b'x')", "pass", "timeout"),
        # Progress, over and over: each such frame once reset the worker's deadline.
        ("pass", f"everywhere({forged({'type': 'progress', 'steps': 1})})", "protocol"),
    ],
    ids=["ignored-alarm", "broken-frame", "forged-progress"],
)
def test_code_that_ignores_its_alarm_is_stopped_by_its_deadline(before, during, kind):
    source = reward(
        f"signal.signal(signal.SIGALRM, signal.SIG_IGN)\n{before}\nwhile True:\n    {during}",
        head=WRITE_EVERYWHERE,
    )
    result, took = timed(source)
    assert isinstance(result, SandboxFailure), result
    assert result.kind == kind, str(result)
    if kind == "timeout":
        assert f"took longer than {LIMIT:g} s" in str(result)
    assert took < LIMIT + KILL_GRACE + SLACK


def test_a_forged_reply_is_checked_as_a_reward():
    source = reward(
        f"everywhere({forged({'type': 'reward', 'value': float('inf')})})\nreturn 1.0",
        head=WRITE_EVERYWHERE,
    )
    result, _ = timed(source)
    assert isinstance(result, SandboxFailure), result
    assert result.kind == "value", str(result)
    assert "finite number" in str(result)


@contextlib.contextmanager
def reward_process(source: str, cars: int) -> Iterator[RewardProcess]:
    """The reward process a rollout's child of ``cars`` cars forks, forked here, with a copy of
    ``source`` loaded per car."""
    process = RewardProcess(LIMIT, 1024 * MiB)
    try:
        process.wait_ready(60.0)
        process.load(source, copies=cars)
        yield process
    finally:
        process.stop()


@pytest.mark.slow
def test_a_step_of_four_cars_each_near_its_limit_passes_and_each_cars_prints_arrive():
    # The time limit is per call: four calls of 0.3 s (1.2 s in all) in one step, under a
    # limit of 0.5 s each, are not late.
    source = reward(
        "time.sleep(0.3)\nprint('car', params['x'])\nreturn params['x']", head="import time\n"
    )
    with reward_process(source, cars=4) as process:
        asked = process.round_trips
        rewards = process.calls([(car, {**PARAMS, "x": float(car)}) for car in range(4)])
        assert process.round_trips == asked + 1
        lines, dropped = process.printed.take()
    assert rewards == [0.0, 1.0, 2.0, 3.0]
    assert (lines, dropped) == (["car 0.0", "car 1.0", "car 2.0", "car 3.0"], 0)


@pytest.mark.slow
def test_a_call_that_outlives_its_alarm_in_one_of_four_cars_is_stopped_by_its_own_deadline():
    # Car 2 catches its alarm and returns 1 s late: within the deadline of a step of four
    # calls, past its own call's. Each car's reply is due by its own call's deadline.
    late = "try:\n    time.sleep(5)\nexcept BaseException:\n    time.sleep(1.0)\nreturn 1.0"
    source = reward(
        f"if params['x'] == 2:\n{textwrap.indent(late, '    ')}\nreturn 1.0", head="import time\n"
    )
    with reward_process(source, cars=4) as process:
        with pytest.raises(RewardFailure) as failed:
            process.calls([(car, {**PARAMS, "x": float(car)}) for car in range(4)])
        assert process.pid is None  # killed from outside
    assert (failed.value.error["kind"], failed.value.car) == ("timeout", 2)
    assert f"took longer than {LIMIT:g} s; it was stopped" in str(failed.value)


@pytest.mark.parametrize(
    ("forgery", "message"),
    [
        ({"type": "error", "kind": "exception", "message": "x", "car": 7}, "other than the one"),
        ({"type": "reward", "value": 1.0, "car": 1}, "other than the one"),  # car 0's turn
        ({"type": "rewards", "values": [1.0, 1.0]}, "answered 'rewards'"),  # a whole step's
    ],
    ids=["unknown-car", "out-of-turn", "whole-step"],
)
def test_a_forged_reply_to_a_step_of_several_cars_is_a_protocol_failure(forgery, message):
    source = reward(f"everywhere({forged(forgery)})\nreturn 1.0", head=WRITE_EVERYWHERE)
    with reward_process(source, cars=2) as process:
        with pytest.raises(RewardFailure) as failed:
            process.calls([(0, PARAMS), (1, PARAMS)])
        assert process.pid is None  # stopped: nothing it says is read again
    assert failed.value.error["kind"] == "protocol"
    assert message in str(failed.value)


def test_a_sandbox_whose_start_fails_is_closed(monkeypatch):
    monkeypatch.setattr(sandbox_package, "GRACE", 0.0)
    sandbox = Sandbox(start_timeout=0.001)  # late by the time it has started
    with pytest.raises(SandboxFailure, match="did not start"), sandbox:
        pass
    assert sandbox._process is None  # closed: its pipes, and its readers told to stop
    assert sandbox._closed.is_set()


def test_a_frame_over_the_size_limit_gets_the_process_killed():
    source = reward(f"everywhere({HEADER.pack(1 << 30)!r})\nreturn 1.0", head=WRITE_EVERYWHERE)
    result, took = timed(source)
    assert isinstance(result, SandboxFailure), result
    assert result.kind == "protocol", str(result)
    assert "over the" in str(result)
    assert took < DEADLINE + SLACK


@pytest.mark.slow
def test_an_endless_line_on_standard_error_costs_the_worker_nothing():
    # About 1 GB written without a newline; read by lines, the worker once kept all of it.
    source = reward("os.write(2, b'x' * 50_000_000)\nreturn 1.0", head="import os\n")
    with Sandbox(call_timeout=5.0) as sandbox:
        sandbox.load(source)
        before = rss()
        for _ in range(20):
            assert sandbox.call(PARAMS) == 1.0
        grown = rss() - before
        assert len(sandbox.stderr_tail) <= STDERR_KEEP
    assert grown < 100 * 1024 * 1024, f"the worker grew by {grown / 2**20:.0f} MiB"


def test_floods_of_frames_and_prints_keep_the_worker_bounded():
    source = reward(
        """
        for _ in range(2000):
            everywhere(b'\\x00\\x00\\x10\\x00' + b'y' * 4096)
            print('z' * 10_000)
        return 1.0
        """,
        head=WRITE_EVERYWHERE,
    )
    with Sandbox(call_timeout=5.0) as sandbox:
        sandbox.load(source)
        before = rss()
        with pytest.raises(SandboxFailure) as failed:
            sandbox.call(PARAMS)
        grown = rss() - before
    assert failed.value.kind == "protocol", str(failed.value)
    assert grown < 100 * 1024 * 1024, f"the worker grew by {grown / 2**20:.0f} MiB"


def test_stat_of_a_path_is_refused():
    result, _ = timed(reward("os.stat('/etc/passwd')\nreturn 1.0", head="import os\n"))
    assert isinstance(result, SandboxFailure), result
    assert "PermissionError" in str(result)


def test_writing_to_the_workers_pipe_is_impossible():
    # The worker's pipe is the child's alone: fd 1 is closed in the reward process.
    result, _ = timed(reward("return float(os.write(1, b'hello'))", head="import os\n"))
    assert isinstance(result, SandboxFailure), result
    assert "Bad file descriptor" in str(result) or "PermissionError" in str(result)


@pytest.mark.parametrize(
    "source",
    [
        "x = " + "-" * 100_000 + "1\n",  # the parser runs out of memory
        "x = " + "+".join(["1"] * 50_000) + "\n",  # the parser runs out of stack
    ],
    ids=["memory", "recursion"],
)
def test_code_nested_too_deep_for_the_parser_is_a_validation_error(source):
    errors, _ = static_problems(source + reward("return 1.0"))
    assert [problem.type for problem in errors] == ["syntax"]
    assert "nested too deeply" in errors[0].message
    result = reward_validate(source=source + reward("return 1.0"), track="rookie-loop")
    assert not result.valid
    # And the sandbox, which does not rely on the static checks, says the same.
    with Sandbox() as sandbox, pytest.raises(SandboxFailure) as failed:
        sandbox.load(source + reward("return 1.0"))
    assert failed.value.kind == "syntax", str(failed.value)


WORKER = """
import sys, time
from sandbox import Sandbox
sandbox = Sandbox(env={"track": "pitlane-oval"})
sandbox.start()
sandbox.load("def reward_function(params):\\n    return 1.0\\n")
print(sandbox._process.pid, flush=True)
time.sleep(600)
"""


def test_nothing_outlives_a_worker_killed_outright():
    worker = subprocess.Popen(
        [sys.executable, "-c", WORKER], stdout=subprocess.PIPE, text=True, cwd=os.getcwd()
    )
    try:
        child = int(worker.stdout.readline())
        grandchildren = children_of(child)
        assert len(grandchildren) == 1, "the child has its reward process"
        (zygote,) = children_of(worker.pid)  # which forked the child (sandbox.zygote)
        assert child in children_of(zygote)
        worker.send_signal(signal.SIGKILL)
        worker.wait()
        deadline = time.monotonic() + 10
        processes = {
            "the sandbox child": child,
            "the reward process": grandchildren[0],
            "the zygote": zygote,
        }
        while time.monotonic() < deadline and any(map(alive, processes.values())):
            time.sleep(0.1)
        assert [name for name, pid in processes.items() if alive(pid)] == [], "outlived a worker"
    finally:
        worker.kill()
        worker.wait()


def test_a_frame_begun_and_never_finished_is_late_by_the_deadline():
    read, write = os.pipe()
    os.set_blocking(read, False)
    try:
        os.write(write, HEADER.pack(100) + b"partial")
        started = time.monotonic()
        with pytest.raises(Late):
            read_frame_by(read, time.monotonic() + 0.3, 1000)
        assert time.monotonic() - started < 0.3 + SLACK
    finally:
        os.close(read)
        os.close(write)


def test_a_reader_that_takes_nothing_makes_a_write_late_by_the_deadline():
    read, write = os.pipe()
    os.set_blocking(write, False)
    try:
        started = time.monotonic()
        with pytest.raises(Late):
            write_by(write, b"x" * 10_000_000, time.monotonic() + 0.3)
        assert time.monotonic() - started < 0.3 + SLACK
    finally:
        os.close(read)
        os.close(write)
