"""Real services for the test suite, loaded as a pytest plugin (``-p tests.services``).

Before Django's settings are read, it starts a throwaway Redis on a free port and points the suite
at it, with a scratch ``var/`` directory; fixtures then start real Celery worker and Daphne
processes on demand.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def parent_of(pid: int) -> int:
    """The parent's process id, from /proc (the command name may hold spaces and parentheses)."""
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def wait_for(condition: Callable[[], bool], what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"gave up waiting for {what} after {timeout:.0f} s")
        time.sleep(0.1)


class RedisServer:
    """A private ``redis-server`` on a free port, with no persistence."""

    def __init__(self, directory: Path) -> None:
        if shutil.which("redis-server") is None:
            raise RuntimeError("redis-server is not installed; `make test` installs it with apt.")
        self.port = free_port()
        self.url = f"redis://127.0.0.1:{self.port}/0"
        self.directory = directory
        directory.mkdir(parents=True, exist_ok=True)
        self.start()

    def start(self) -> None:
        self.process = subprocess.Popen(
            [
                "redis-server",
                "--bind",
                "127.0.0.1",
                "--port",
                str(self.port),
                "--dir",
                str(self.directory),
                "--save",
                "",
                "--appendonly",
                "no",
                "--daemonize",
                "no",
                "--loglevel",
                "warning",
            ],
            stdout=subprocess.DEVNULL,
        )
        wait_for(self.answers, f"Redis on port {self.port}", timeout=15)

    def restart(self) -> None:
        """Stop and start again on the same port, with nothing kept: a Redis restart."""
        self.stop()
        self.start()

    def save(self) -> None:
        """Write the data to the directory's dump, which the next start loads: a restart after
        it keeps the data, as a Redis with persistence does."""
        # SAVE answers once the whole dump is written: on a loaded 2-core box (the whole suite
        # beside it) that took more than 10 s once.
        with socket.create_connection(("127.0.0.1", self.port), timeout=60) as connection:
            connection.sendall(b"SAVE\r\n")
            if not connection.recv(16).startswith(b"+OK"):
                raise RuntimeError(f"Redis on port {self.port} did not save its data")

    def answers(self) -> bool:
        try:
            with socket.create_connection(("127.0.0.1", self.port), timeout=0.5) as connection:
                connection.sendall(b"PING\r\n")
                return connection.recv(16).startswith(b"+PONG")
        except OSError:
            return False

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(10)


SUITE_REDIS = pytest.StashKey[RedisServer]()  # the suite's Redis, in the config's stash


class ServiceProcess:
    """A process of ours (Celery worker, Daphne) running against the test settings and database."""

    def __init__(self, command: list[str], env: dict[str, str], log: Path) -> None:
        self.log = log
        with open(log, "wb") as output:
            self.process = subprocess.Popen(
                command, cwd=ROOT, env=env, stdout=output, stderr=subprocess.STDOUT
            )

    @property
    def pid(self) -> int:
        return self.process.pid

    def ensure_running(self) -> None:
        if self.process.poll() is not None:
            raise RuntimeError(
                f"{self.process.args[:4]} exited with {self.process.returncode}:\n"
                + self.log.read_text()[-4000:]
            )

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def service_env(database: str) -> dict[str, str]:
    """The environment for a process that must share the suite's Redis and test database."""
    env = dict(os.environ)
    env.update(
        DJANGO_SETTINGS_MODULE="console.settings.test",
        DATABASE_URL=f"sqlite:///{database}",
        PYTHONUNBUFFERED="1",
    )
    return env


def daphne_started(
    database: str, log: Path, settings: dict[str, str] | None = None
) -> tuple[ServiceProcess, int]:
    """Daphne serving console.asgi on a free port, listening, with ``settings`` added to its
    environment; its process and port (stop it)."""
    port = free_port()
    process = ServiceProcess(
        python_module("daphne", "-b", "127.0.0.1", "-p", str(port), "console.asgi:application"),
        env={**service_env(database), **(settings or {})},
        log=log,
    )

    def listening() -> bool:
        process.ensure_running()
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
            return True
        except OSError:
            return False

    try:
        wait_for(listening, "Daphne to listen")
    except BaseException:
        process.stop()
        raise
    return process, port


def python_module(*args: str) -> list[str]:
    return [sys.executable, "-m", *args]


@pytest.hookimpl(wrapper=True)
def pytest_load_initial_conftests(early_config, parser, args):
    scratch = Path(tempfile.mkdtemp(prefix="pitlane-tests-"))
    os.environ["PITLANE_VAR_DIR"] = str(scratch / "var")
    os.environ["PITLANE_TEST_DB"] = str(scratch / "test.sqlite3")
    redis_server = RedisServer(scratch / "redis")
    os.environ["REDIS_URL"] = redis_server.url
    early_config.stash[SUITE_REDIS] = redis_server
    early_config.add_cleanup(lambda: shutil.rmtree(scratch, ignore_errors=True))
    early_config.add_cleanup(redis_server.stop)
    return (yield)
