"""`make run`'s supervisor, run as a racer runs it: a real Redis, worker and Daphne, then Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.services import ROOT, free_port, parent_of, wait_for


def environment(var_dir: Path, port: int, redis_port: int) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
    env.pop("REDIS_URL", None)  # so the supervisor starts its own Redis
    env.update(
        DJANGO_SETTINGS_MODULE="console.settings.dev",
        PITLANE_VAR_DIR=str(var_dir),
        PITLANE_PORT=str(port),
        PITLANE_REDIS_PORT=str(redis_port),
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


@pytest.fixture(scope="module")
def console_running(tmp_path_factory) -> Iterator[tuple[subprocess.Popen, dict[str, str], str]]:
    var_dir = tmp_path_factory.mktemp("var")
    port, redis_port = free_port(), free_port()
    env = environment(var_dir, port, redis_port)
    process = runconsole(env)
    output = []
    for line in process.stdout:
        output.append(line)
        if "Pitlane is running" in line:
            break
    else:
        pytest.fail("runconsole exited before serving:\n" + "".join(output))
    yield process, env, "".join(output)
    if process.poll() is None:
        process.kill()
        process.wait()


def test_it_serves_the_console_with_redis_and_a_worker(console_running):
    _, env, output = console_running
    port = env["PITLANE_PORT"]
    assert f"Pitlane is running: http://127.0.0.1:{port}" in output
    assert "8 built-in tracks loaded" in output
    assert (Path(env["PITLANE_VAR_DIR"]) / "secret_key").stat().st_mode & 0o777 == 0o600
    assert (Path(env["PITLANE_VAR_DIR"]) / "redis" / "appendonlydir").is_dir()
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=10) as response:
        assert json.load(response)["status"] == "ok"
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/races/", timeout=10) as response:
        assert "Open time trial" in response.read().decode()


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


def test_ctrl_c_stops_everything_it_started(console_running):
    process, env, _ = console_running
    started = children_of(process.pid)
    assert len(started) == 3  # Redis, the Celery worker, Daphne
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=60) == 0
    assert "Stopping Pitlane..." in process.stdout.read()
    for pid in started:
        assert not Path(f"/proc/{pid}").exists(), f"process {pid} outlived Ctrl-C"
    for port in (env["PITLANE_PORT"], env["PITLANE_REDIS_PORT"]):
        wait_for(lambda port=port: not listening(int(port)), f"port {port} to close", timeout=10)
