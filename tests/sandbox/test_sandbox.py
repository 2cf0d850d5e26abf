"""The hostile suite: racers' code trying what it must not. Each attempt is stopped, reported in
words a racer understands, and leaves this process (standing in for the worker) alive, with
nothing written and nothing sent. These tests run the sandbox directly; the static checks of
validation are feedback, not the boundary, so they are not in the way here."""

import os
import socket
from pathlib import Path

import msgpack
import pytest

import sandbox as sandbox_package
from rl.wire import decode_array
from sandbox import CHILD_ENVIRONMENT, MiB, Sandbox, SandboxFailure, self_test
from sandbox.spawner import Zygote
from tests.helpers.sandbox import PARAMS, POLICY, assert_stopped, driving, outcome, reward


def test_the_sandbox_holds_on_this_machine():
    result = self_test()
    assert result.ok, result.detail
    assert result.escaped == ()


def test_a_good_reward_function_runs_and_its_prints_become_log_lines():
    with Sandbox() as sandbox:
        sandbox.load(reward("print('width', params['track_width'])\nreturn params['x'] * 2"))
        assert sandbox.call(PARAMS) == 2.0
        assert list(sandbox.logs) == ["width 0.76"]


def test_reading_etc_passwd_is_refused():
    result = outcome(reward("return len(open('/etc/passwd').read())"))
    assert_stopped(result, "exception", "line 2", "PermissionError", "Operation not permitted")


def test_reading_a_secret_file_is_refused(tmp_path):
    secret = tmp_path / "secret_key"
    secret.write_text("s3cr3t")
    result = outcome(reward(f"return len(open({str(secret)!r}).read())"))
    assert_stopped(result, "exception", "PermissionError")


def test_the_workers_environment_is_not_there(monkeypatch):
    monkeypatch.setenv("PITLANE_TEST_SECRET", "s3cr3t")
    # What the child's own libraries set for themselves when they load is no leak.
    set_by_libraries = {"LC_CTYPE", "LD_LIBRARY_PATH", "PYGAME_HIDE_SUPPORT_PROMPT"}
    ours = sorted(set(os.environ) - set(CHILD_ENVIRONMENT) - set_by_libraries)
    assert "PITLANE_TEST_SECRET" in ours and "REDIS_URL" in ours
    source = "import os\n" + reward(f"return float(len(set(os.environ) & set({ours!r})))")
    assert outcome(source) == 0.0
    result = outcome(
        "import os\n" + reward("return len(open(f'/proc/{os.getppid()}/environ').read())")
    )
    assert_stopped(result, "exception", "PermissionError")


def test_the_racers_code_finds_nothing_about_the_host_in_its_environment():
    """Not even what the child's libraries set as they load (cv2: LD_LIBRARY_PATH, naming
    where the console is installed)."""
    with Sandbox() as sandbox:
        sandbox.load("import os\n" + reward("print(sorted(os.environ))\nreturn 1.0"))
        assert sandbox.call(PARAMS) == 1.0
        assert list(sandbox.logs) == [str(sorted(CHILD_ENVIRONMENT))]
    source = "import os\n" + reward("return float(sum('/' in v for v in os.environ.values()))")
    assert outcome(source) == 0.0


def test_writing_a_file_is_refused(tmp_path):
    target = tmp_path / "written.txt"
    result = outcome(reward(f"open({str(target)!r}, 'w').write('x')\nreturn 1.0"))
    assert_stopped(result, "exception", "PermissionError")
    assert not target.exists()


def test_connecting_to_a_listening_socket_is_refused():
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        listener.settimeout(0.5)
        port = listener.getsockname()[1]
        result = outcome(
            "import socket\n"
            + reward(f"socket.create_connection(('127.0.0.1', {port}), timeout=1)\nreturn 1.0")
        )
        assert_stopped(result, "exception", "PermissionError")
        with pytest.raises(TimeoutError):
            listener.accept()  # nothing came in


@pytest.mark.slow
@pytest.mark.parametrize(
    "attack",
    [
        "import subprocess\nsubprocess.run(['touch', MARKER])",
        "import os\nos.system('touch ' + MARKER)\nif os.path.exists(MARKER): return 1e9",
        "import os\nwhile True:\n    os.fork()",
        "import os\nos.execv('/usr/bin/touch', ['touch', MARKER])",
        "import ctypes\nctypes.CDLL(None).system(('touch ' + MARKER).encode())",
    ],
    ids=["subprocess", "os.system", "fork-bomb", "exec", "ctypes-system"],
)
def test_starting_processes_is_refused(tmp_path, attack):
    marker = tmp_path / "marker"
    result = outcome(reward(f"MARKER = {str(marker)!r}\n{attack}\nreturn 1.0"))
    assert not marker.exists()
    if not isinstance(result, SandboxFailure):
        assert result == 1.0  # os.system and ctypes' system() report failure, not raise
    else:
        assert result.kind in ("exception", "import"), str(result)


def test_walking_object_subclasses_to_popen_is_refused(tmp_path):
    marker = tmp_path / "marker"
    source = reward(f"""
        for cls in ().__class__.__base__.__subclasses__():
            if cls.__name__ == 'Popen':
                cls(['touch', {str(marker)!r}])
                return 1e9
        return 0.5
    """)
    result = outcome(source)
    assert not marker.exists()
    if isinstance(result, SandboxFailure):
        assert_stopped(result, "exception", "PermissionError")
    else:
        assert result == 0.5  # Popen was not reachable at all


def test_allocating_10_gb_is_stopped_by_the_memory_limit():
    assert_stopped(
        outcome(reward("x = bytearray(10 * 1024 ** 3)\nreturn 1.0")), "memory", "ran out of memory"
    )
    numpy_attack = "import numpy as np\n" + reward("return float(np.ones(1_250_000_000).sum())")
    assert_stopped(outcome(numpy_attack), "memory")


def test_an_infinite_loop_is_stopped_at_the_time_limit():
    result = outcome(reward("while True:\n    pass"), call_timeout=0.5)
    assert_stopped(result, "timeout", "took longer than 0.5 s", "line 2")


def test_a_loop_that_blocks_the_alarm_is_killed_from_outside():
    source = "import signal\n" + reward(
        "signal.signal(signal.SIGALRM, signal.SIG_IGN)\nwhile True:\n    pass"
    )
    result = outcome(source, call_timeout=0.5)
    assert_stopped(result, "timeout", "took longer than 0.5 s", "stopped")


@pytest.mark.slow
def test_numpy_file_loading_and_ctypes_libraries_are_refused(tmp_path):
    (tmp_path / "libevil.so").write_bytes(b"\x7fELF not really")
    for body in (
        "return float(np.fromfile('/etc/passwd', dtype=np.uint8).sum())",
        "return float(np.loadtxt('/etc/hostname').sum())",
        f"np.ctypeslib.load_library('libevil', {str(tmp_path)!r})\nreturn 1.0",
    ):
        result = outcome("import numpy as np\n" + reward(body))
        assert isinstance(result, SandboxFailure), body
        assert result.kind == "exception", (body, str(result))


def test_a_ctypes_crash_is_reported_and_this_process_carries_on():
    crash = "ctypes.cast(ctypes.c_void_p(8), ctypes.POINTER(ctypes.c_long)).contents.value"
    result = outcome("import ctypes\n" + reward(f"return float({crash})"))
    assert_stopped(result, "crashed", "killed by SIGSEGV")
    assert outcome(reward("return 1.0")) == 1.0  # the next sandbox works as ever


def test_exiting_is_reported():
    assert_stopped(outcome("import sys\n" + reward("sys.exit(3)")), "exception", "called exit()")
    assert_stopped(outcome("import os\n" + reward("os._exit(3)")), "crashed", "status 3")


def test_an_exception_is_reported_with_its_line():
    result = outcome(reward("a = 1\nreturn a / 0"))
    assert_stopped(result, "exception", "line 3", "ZeroDivisionError: division by zero")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("value", "message"),
    [("float('nan')", "finite number"), ("'fast'", "str 'fast', not a number"),
     ("1e9", "within ±100000"), ("None", "NoneType None, not a number")],
)  # fmt: skip
def test_a_bad_return_value_is_reported(value, message):
    assert_stopped(outcome(reward(f"return {value}")), "value", message)


def test_a_module_that_fails_on_import_is_reported_as_an_import_error():
    result = outcome("import os\nimport definitely_not_a_module\n" + reward("return 1.0"))
    assert_stopped(result, "import", "line 2", "No module named 'definitely_not_a_module'")


def test_code_without_a_reward_function_is_reported():
    assert_stopped(
        outcome("def reward(params):\n    return 1.0\n"),
        "definition",
        "must define reward_function(params)",
    )


@pytest.mark.slow
def test_an_episode_runs_the_simulator_and_the_reward_inside_the_sandbox():
    with driving({"track": "pitlane-oval"}) as sandbox:
        sandbox.load(reward("return 1.0 if params['all_wheels_on_track'] else 0.0"))
        episodes = [sandbox.episode(mode) for mode in ("random", "explore", "evaluate")]
    for episode in episodes:
        summary = episode["summary"]
        assert summary["steps"] >= 1
        assert 0 < summary["reward"] <= summary["steps"]  # a point for each step on the track
    assert all(isinstance(episode.get("payload"), bytes) for episode in episodes[:2])
    assert "payload" not in episodes[2]  # an evaluation sends its summary alone


CRASH = "ctypes.cast(ctypes.c_void_p(8), ctypes.POINTER(ctypes.c_long)).contents.value"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("failing", "expected"),
    [
        ("return {}['missing']", "at step 3 (in_progress), line 4: KeyError: 'missing'"),
        # The reward process stopped from outside, or gone: its call was the step's (car 0's).
        (f"return float({CRASH})", "at step 3 (in_progress): The reward function's process "
         "stopped: it was killed by SIGSEGV (a crash, for example from ctypes)."),
        ("signal.signal(signal.SIGALRM, signal.SIG_IGN)\n    while True: pass",
         "at step 3 (in_progress): The reward function took longer than 0.5 s; it was stopped."),
    ],
    ids=["exception", "crashed", "ignored-alarm"],
)  # fmt: skip
def test_an_episode_names_the_step_and_status_where_the_reward_function_failed(failing, expected):
    source = "import ctypes, signal\n" + reward(
        f"if params['steps'] == 3:\n    {failing}\nreturn 1.0"
    )
    with Sandbox(
        env={"track": "pitlane-oval"}, policy=POLICY, call_timeout=0.5, memory_allowance=1024 * MiB
    ) as sandbox:
        sandbox.load(source)
        with pytest.raises(SandboxFailure) as failed:
            sandbox.episode("random")
    assert str(failed.value) == expected


BOXES = {
    "track": "pitlane-oval",
    "race_type": "OBJECT_AVOIDANCE",
    "objects": {"count": 6},
    "sensors": ["FRONT_FACING_CAMERA", "LIDAR"],
}


@pytest.mark.slow
def test_a_rollouts_car_sees_boxes_through_pybullet_in_the_sealed_child():
    # PyBullet is connected before the child seals: it can open no file after.
    with Sandbox(env=BOXES, policy=POLICY, memory_allowance=1024 * MiB) as sandbox:
        sandbox.load(reward("return 1.0"))
        for _ in range(20):
            payload = msgpack.unpackb(sandbox.episode("random")["payload"])
            lidar = decode_array(payload["arrays"]["obs:LIDAR"], "float32", (None, None))
            if (lidar < 1.0).any():  # a ray stopped short of its range: at a box
                break
        else:
            pytest.fail("no box seen in 20 episodes")


@pytest.mark.slow
@pytest.mark.parametrize(
    "sensors",
    [["FRONT_FACING_CAMERA"], ["FRONT_FACING_CAMERA", "LIDAR"]],
    ids=["touching-while-driving", "seen-at-the-start"],
)
def test_a_rollout_without_pybullet_says_so_when_its_car_nears_a_box(
    tmp_path, monkeypatch, sensors
):
    from jobs.rollouts import failure_words

    (tmp_path / "pybullet.py").write_text("raise ImportError('not installed')\n")
    # The children of a zygote that imports from there, where PyBullet "is not installed".
    zygote = Zygote({**CHILD_ENVIRONMENT, "PYTHONPATH": str(tmp_path)})
    monkeypatch.setattr(sandbox_package, "_zygote", lambda: zygote)
    env = {**BOXES, "sensors": sensors}
    sandbox = Sandbox(env=env, policy=POLICY, memory_allowance=1024 * MiB)
    with pytest.raises(SandboxFailure) as failed, sandbox:  # at the start, or in an episode
        sandbox.load(reward("return 1.0"))
        for _ in range(20):
            sandbox.episode("random")
    zygote.stop()
    assert failed.value.kind == "simulation"
    assert failure_words(failed.value, 0) == (
        "Simulation worker 1 failed (not your reward function): Object avoidance and "
        "head-to-bot races need PyBullet, which is not installed on this simulation machine; "
        "time trials run without it."
    )


def test_nothing_was_left_behind_in_tmp():
    assert not Path("/tmp/pitlane-sandbox-probe").exists()
    assert os.getpid() > 0  # still here


def test_a_sandbox_of_a_lighter_job_runs_its_child_and_the_racers_code_nicer():
    """A job with a smaller share of the machine (jobs.shares) drives behind the others: its
    child and the reward process the racer's code runs in, both, at the niceness asked for."""
    ours = os.getpriority(os.PRIO_PROCESS, 0)
    with Sandbox(niceness=3) as sandbox:
        sandbox.load(reward("return 1.0"))
        assert sandbox.call(PARAMS) == 1.0
        group = sandbox._process.pid
        niceness = {}
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except OSError:  # a process of someone else's that ended meanwhile
                continue
            if int(fields[2]) == group:  # the process group: the child and what it started
                niceness[int(stat.parent.name)] = int(fields[16])
    assert len(niceness) >= 2  # the child and its reward process
    assert set(niceness.values()) == {min(ours + 3, 19)}
