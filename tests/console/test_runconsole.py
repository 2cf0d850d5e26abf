"""`make run`'s supervisor, run as a racer runs it: a real Redis, worker and Daphne, then Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import socket
import sqlite3
import stat
import subprocess
import sys
import threading
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
import redis

from common.health import live_workers
from tests.helpers.private_files import an_install_from_before, read_as_another_user
from tests.services import ROOT, free_port, parent_of, wait_for

pytestmark = pytest.mark.slow  # each test starts the console: Redis, workers and Daphne


def environment(var_dir: Path, port: int, redis_port: int) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
    env.pop("REDIS_URL", None)  # so the supervisor starts its own Redis
    env.update(
        DJANGO_SETTINGS_MODULE="console.settings.dev",
        PITLANE_VAR_DIR=str(var_dir),
        PITLANE_PORT=str(port),
        PITLANE_REDIS_PORT=str(redis_port),
        PITLANE_TRAINERS="1",
        PITLANE_WORKER_CONCURRENCY="1",
        PYTHONUNBUFFERED="1",
    )
    return env


def runconsole(env: dict[str, str], **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "manage.py", "runconsole"],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        **kwargs,
    )


def listening(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
        return True
    except OSError:
        return False


class Output:
    """What a running console prints, read as it comes by a thread of its own."""

    def __init__(self, process: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self.thread = threading.Thread(target=self.lines.extend, args=(process.stdout,))
        self.thread.start()

    def __str__(self) -> str:
        return "".join(self.lines)

    def wait_for(self, text: str, process: subprocess.Popen, timeout: float = 60) -> None:
        def printed() -> bool:
            if process.poll() is not None:
                self.thread.join()
            return text in str(self) or process.poll() is not None

        wait_for(printed, f"the console to print {text!r}", timeout=timeout)
        assert text in str(self), f"the console exited without printing {text!r}:\n{self}"


@pytest.fixture(scope="module")
def console_running(tmp_path_factory) -> Iterator[tuple[subprocess.Popen, dict[str, str], Output]]:
    var_dir = tmp_path_factory.mktemp("var")
    # A model's file that an install from before left readable by everyone (its database and
    # Redis's files made up would not start): test_it_lets_no_other_user_read_the_data_directory
    an_install_from_before(var_dir, ("media/models/1/best.pt",))
    port, redis_port = free_port(), free_port()
    env = environment(var_dir, port, redis_port)
    process = runconsole(env)
    output = Output(process)
    output.wait_for("Pitlane is running", process, timeout=120)
    yield process, env, output
    if process.poll() is None:
        process.kill()
        process.wait()


def test_it_serves_the_console_with_redis_and_a_worker_per_queue(console_running):
    _, env, printed = console_running
    output = str(printed)
    port = env["PITLANE_PORT"]
    assert f"Pitlane is running: http://127.0.0.1:{port}" in output
    assert "78 built-in tracks loaded: 8 of Pitlane's and 70 of DeepRacer's." in output
    # What it chose for the machine, the variables set winning, and how to choose otherwise
    assert "This machine: " in output
    assert "Training 1 job at once (PITLANE_TRAINERS), 1 simulation process for" in output
    assert "set any of them to choose otherwise." in output
    assert (Path(env["PITLANE_VAR_DIR"]) / "secret_key").stat().st_mode & 0o777 == 0o600
    assert (Path(env["PITLANE_VAR_DIR"]) / "redis" / "appendonlydir").is_dir()
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=10) as response:
        assert json.load(response)["status"] == "ok"
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/races/", timeout=10) as response:
        assert "Open time trial" in response.read().decode()
    # Each queue has a worker of its own: no kind of work can take the processes of another.
    assert {tuple(w["queues"]) for w in workers_of(env)} == {
        ("training",),
        ("simulation",),
        ("rescoring",),
    }
    # Each child is given the figures the supervisor chose, so that all of them agree
    for worker in workers_of(env):
        given = Path(f"/proc/{worker['pid']}/environ").read_bytes().split(b"\0")
        assert b"PITLANE_TRAINERS=1" in given
        assert any(name.startswith(b"PITLANE_CARS_PER_WORKER=") for name in given)
    # The re-scoring gives the cores way to the trainings and the rest; they keep their priority
    niceness = {w["queues"][0]: os.getpriority(os.PRIO_PROCESS, w["pid"]) for w in workers_of(env)}
    ours = os.getpriority(os.PRIO_PROCESS, 0)
    assert niceness == {"training": ours, "simulation": ours, "rescoring": min(ours + 10, 19)}


def test_it_lets_no_other_user_read_the_data_directory(console_running):
    _, env, _ = console_running
    var = Path(env["PITLANE_VAR_DIR"])
    redis_of(env).save()  # Redis's dump, born as the console writes it
    with sqlite3.connect(var / "db.sqlite3") as database:  # its WAL and shared memory open
        database.execute("SELECT count(*) FROM django_session").fetchone()
        assert (var / "db.sqlite3-wal").exists() and (var / "db.sqlite3-shm").exists()
        names = [
            ".",
            "db.sqlite3",
            "db.sqlite3-wal",
            "db.sqlite3-shm",
            "redis/dump.rdb",
            "redis/redis.log",
            "redis/appendonlydir",
            "media/models/1/best.pt",  # left readable by an install from before
            "uploads-tmp",
            "secret_key",
        ]
        assert read_as_another_user(var, names) == dict.fromkeys(names, "EACCES")
        # Nor would they, could they reach var/: nothing in it is the group's or others'.
        opened = {
            str(path.relative_to(var)): oct(stat.S_IMODE(path.stat().st_mode))
            for path in var.rglob("*")
            if not path.is_symlink() and path.stat().st_mode & 0o077
        }
        assert opened == {}


def redis_of(env: dict[str, str]) -> redis.Redis:
    password = (Path(env["PITLANE_VAR_DIR"]) / "redis_password").read_text().strip()
    url = f"redis://:{password}@127.0.0.1:{env['PITLANE_REDIS_PORT']}/0"
    return redis.Redis.from_url(url, socket_connect_timeout=2, socket_timeout=5)


def workers_of(env: dict[str, str]) -> list[dict]:
    return live_workers(redis_of(env))


def test_a_second_run_is_refused_with_a_clear_message(console_running):
    _, env, _ = console_running
    second = runconsole(env)
    output, _ = second.communicate(timeout=60)
    assert second.returncode == 1
    assert "Pitlane is already running" in output
    assert "Traceback" not in output


def test_a_port_in_use_is_named(console_running, tmp_path):
    _, env, _ = console_running
    other = environment(tmp_path, int(env["PITLANE_PORT"]), free_port())
    second = runconsole(other)
    output, _ = second.communicate(timeout=60)
    assert second.returncode == 1
    assert f"Port {env['PITLANE_PORT']} is already in use by another program" in output
    assert f"PITLANE_PORT={int(env['PITLANE_PORT']) + 1} make run" in output
    assert "Traceback" not in output


def children_of(pid: int) -> set[int]:
    children = set()
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            if parent_of(int(entry.name)) == pid:
                children.add(int(entry.name))
        except OSError:
            continue  # the process ended while we looked
    return children


def test_a_child_that_dies_is_started_again_and_says_so(console_running):
    process, env, output = console_running
    before = children_of(process.pid)
    (worker,) = [w for w in workers_of(env) if w["queues"] == ["simulation"]]
    redis_pid = next(pid for pid in before if "redis-server" in command_of(pid))
    pool = group_of(worker["pid"])
    assert len(pool) > 1  # the worker, its pool's process and the scheduler inside it
    os.kill(worker["pid"], signal.SIGKILL)
    os.kill(redis_pid, signal.SIGKILL)
    output.wait_for("The simulation worker stopped unexpectedly (exit status -9)", process)
    output.wait_for("The Redis stopped unexpectedly (exit status -9)", process)
    output.wait_for("Started the simulation worker again", process)
    output.wait_for("Started the Redis again", process)

    def back() -> bool:
        try:
            return any(w["queues"] == ["simulation"] for w in workers_of(env))
        except redis.RedisError:
            return False

    wait_for(back, "the new simulation worker to report in", timeout=60)
    assert process.poll() is None  # the console goes on
    assert len(children_of(process.pid)) == len(before)
    assert not [pid for pid in pool if running(pid)]  # no orphan of its pool lives on


def running(pid: int) -> bool:
    """Whether ``pid`` runs: not ended, and not a zombie waiting for its new parent to reap it."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def group_of(leader: int) -> set[int]:
    """The processes of ``leader``'s process group (each child of the console leads its own)."""
    members = set()
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            if int((entry / "stat").read_text().rsplit(")", 1)[1].split()[2]) == leader:
                members.add(int(entry.name))
        except (OSError, IndexError, ValueError):
            continue  # the process ended while we looked
    return members


def command_of(pid: int) -> str:
    return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()


def test_ctrl_c_stops_everything_it_started(console_running):
    process, env, output = console_running
    started = children_of(process.pid)
    assert len(started) == 5  # Redis, the training, simulation and re-scoring workers, Daphne
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=60) == 0
    output.thread.join()
    assert "Stopping Pitlane..." in str(output)
    for pid in started:
        assert not Path(f"/proc/{pid}").exists(), f"process {pid} outlived Ctrl-C"
    for port in (env["PITLANE_PORT"], env["PITLANE_REDIS_PORT"]):
        wait_for(lambda port=port: not listening(int(port)), f"port {port} to close", timeout=10)
