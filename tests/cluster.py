"""Pitlane spread over several machines, all on this one: what ``make cluster`` serves and
``tests/cluster/`` drives.

    python -m tests.cluster [--simulation 2]      # make cluster: serve until Ctrl-C

The shared services are PostgreSQL (a throwaway cluster), Redis and an S3 API (moto's server,
which the storage tests use too). Each "machine" is its own process group in a folder of its own:
``code/``, a copy of nothing but the repository's files, and ``var/``, its ``PITLANE_VAR_DIR``;
it shares only the virtualenv's libraries and the services' addresses with the others, exactly
the environment docs/operating.md's "Running on several machines" gives. The web machine
serves Daphne with the production settings behind what an HTTPS proxy would send
(``X-Forwarded-Proto``); one machine serves the ``training`` queue and the others the
``simulation`` queue.
"""

from __future__ import annotations

import argparse
import logging
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tests.services import RedisServer, free_port, wait_for

ROOT = Path(__file__).resolve().parent.parent
PYTHON = sys.executable
BIN = Path(sys.executable).parent  # the virtualenv's commands: .venv/bin/daphne, .venv/bin/celery
BUCKET = "pitlane-cluster"
SECRET_KEY = "cluster-" + "k" * 50  # every web machine shares it; a throwaway cluster's own
OURS = ("DJANGO_", "PITLANE_", "DATABASE_", "REDIS_", "AWS_")  # the settings' variables


class Postgres:
    """A throwaway PostgreSQL cluster on a free local port, which can be stopped and started
    again (a database outage). PostgreSQL refuses to run as root: as root it runs as ``nobody``,
    in a folder of its own under /tmp (which ``nobody`` can reach, unlike root's folders)."""

    def __init__(self) -> None:
        folder = Path(tempfile.mkdtemp(prefix="pitlane-pg-"))
        self.folder, self.data, self.port = folder, folder / "data", free_port()
        self.as_user = ["runuser", "-u", "nobody", "--"] if os.geteuid() == 0 else []
        if self.as_user:
            shutil.chown(folder, "nobody")
        subprocess.run(
            [
                *self.as_user,
                pg_binary("initdb"),
                "-D",
                str(self.data),
                "-U",
                "postgres",
                "--auth=trust",
                "--no-sync",
                "-E",
                "UTF8",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        self.url = f"postgres://postgres@127.0.0.1:{self.port}/postgres"
        self.start()

    def start(self) -> None:
        options = (
            f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 -c fsync=off "
            "-c max_connections=200"
        )
        subprocess.run(
            [
                *self.as_user,
                pg_binary("pg_ctl"),
                "-D",
                str(self.data),
                "-o",
                options,
                "-l",
                str(self.folder / "log"),
                "-w",
                "start",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )

    def stop(self) -> None:
        subprocess.run(
            [*self.as_user, pg_binary("pg_ctl"), "-D", str(self.data), "-m", "fast", "stop"],
            check=False,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )

    def remove(self) -> None:
        self.stop()
        shutil.rmtree(self.folder, ignore_errors=True)


def pg_binary(name: str) -> str:
    found = shutil.which(name) or next(
        iter(sorted(Path("/usr/lib/postgresql").glob(f"*/bin/{name}"))), None
    )
    if found is None:
        raise RuntimeError(
            "PostgreSQL is not installed: `apt-get install postgresql` (`make test` and `make "
            "bench` install it), then run again."
        )
    return str(found)


class S3Server:
    """moto's S3 API server on a free port, in this process, with the cluster's bucket."""

    def __init__(self) -> None:
        from moto.server import ThreadedMotoServer

        logging.getLogger("werkzeug").setLevel(logging.WARNING)  # a line per request, else
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.server = ThreadedMotoServer(ip_address="127.0.0.1", port=self.port, verbose=False)
        self.server.start()
        self.client().create_bucket(Bucket=BUCKET)

    def client(self):
        import boto3

        return boto3.client(
            "s3",
            endpoint_url=self.url,
            region_name="us-east-1",
            aws_access_key_id="cluster",
            aws_secret_access_key="cluster",
        )

    def keys(self, prefix: str = "") -> list[str]:
        pages = (
            self.client().get_paginator("list_objects_v2").paginate(Bucket=BUCKET, Prefix=prefix)
        )
        return [item["Key"] for page in pages for item in page.get("Contents", [])]

    def stop(self) -> None:
        self.server.stop()


class Machine:
    """One machine: ``code/`` (a copy of the repository's files), ``var/`` and a process group
    per command it runs, so that killing the machine kills everything it started."""

    def __init__(self, name: str, folder: Path, env: dict[str, str]) -> None:
        self.name, self.folder = name, folder
        self.code, self.var = folder / "code", folder / "var"
        self.var.mkdir(parents=True)
        _copy_code(self.code)
        self.env = {**env, "PITLANE_VAR_DIR": str(self.var)}
        self.processes: list[subprocess.Popen] = []
        # the machine's settings, for an operator's commands: `. env` in its folder
        (folder / "env").write_text(
            "".join(
                f"export {key}={shlex.quote(value)}\n"
                for key, value in sorted(self.env.items())
                if key.startswith(OURS)
            )
        )

    def run(self, *args: str) -> str:
        """``python ARGS`` on this machine, to its end; its output."""
        done = subprocess.run(
            [PYTHON, *args], cwd=self.code, env=self.env, capture_output=True, text=True
        )
        if done.returncode:
            raise RuntimeError(f"{self.name}: {' '.join(args)} failed:\n{done.stdout}{done.stderr}")
        return done.stdout

    def start(self, command: Path, *args: str) -> subprocess.Popen:
        """A long-running command on this machine, in a process group of its own."""
        log = open(self.folder / "log", "ab")  # noqa: SIM115 (the process holds it)
        process = subprocess.Popen(
            [str(command), *args],
            cwd=self.code,
            env=self.env,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        log.close()
        self.processes.append(process)
        return process

    def kill(self) -> None:
        """Pull the machine's plug: every process it started dies at once."""
        for process in self.processes:
            with _gone():
                os.killpg(process.pid, signal.SIGKILL)
            process.wait()
        self.processes = []

    def stop(self) -> None:
        for process in self.processes:
            with _gone():
                os.killpg(process.pid, signal.SIGTERM)
        for process in self.processes:
            try:
                process.wait(20)
            except subprocess.TimeoutExpired:
                with _gone():
                    os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        self.processes = []

    def log(self) -> str:
        path = self.folder / "log"
        return path.read_text(errors="replace") if path.exists() else ""

    def files(self) -> list[str]:
        """What this machine keeps under its ``var/``, relative to it."""
        return sorted(str(p.relative_to(self.var)) for p in self.var.rglob("*") if p.is_file())


class _gone:
    """Ignore a process (group) that has already exited."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, value, traceback) -> bool:
        return kind is ProcessLookupError


def _copy_code(destination: Path) -> None:
    """The repository's files (tracked, and new ones git does not ignore), nothing else: no
    ``var/``, no virtualenv, no build output."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        check=True,
        capture_output=True,
    ).stdout.split(b"\0")
    for name in filter(None, (item.decode() for item in listed)):
        source = ROOT / name
        if source.is_file():
            target = destination / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


class Cluster:
    """PostgreSQL, Redis and S3, a web machine, ``training`` training machines and
    ``simulation`` simulation machines (of ``processes`` worker processes each), each started as
    docs/operating.md's "Running on several machines" says. ``settings``: more environment
    variables for every machine."""

    def __init__(
        self,
        folder: Path,
        *,
        simulation: int = 2,
        training: int = 1,
        port: int | None = None,
        proxied: bool = True,
        settings: dict[str, str] | None = None,
        processes: int = 2,
    ) -> None:
        self.folder, self.processes = folder, processes
        self.postgres = Postgres()
        self.redis = RedisServer(folder / "redis")
        self.s3 = S3Server()
        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        env = {
            **cluster_env(self.postgres.url, self.redis.url, self.s3.url),
            "PITLANE_TRAINERS": str(training),  # the queue's words count every machine's trainers
            **(settings or {}),
        }
        if not proxied:  # a browser straight at Daphne: no redirect to the HTTPS it lacks
            env["PITLANE_SSL_REDIRECT"] = "false"
        self.web = Machine("web", folder / "web", env)
        self.training = [
            Machine(f"training-{n}", folder / f"training-{n}", env) for n in range(1, training + 1)
        ]
        self.simulation = [
            Machine(f"simulation-{n}", folder / f"simulation-{n}", env)
            for n in range(1, simulation + 1)
        ]

    @property
    def machines(self) -> list[Machine]:
        return [self.web, *self.training, *self.simulation]

    def start(self) -> None:
        # once per release, on one machine
        self.web.run("manage.py", "migrate", "--noinput")
        self.web.run("manage.py", "collectstatic", "--noinput")
        self.web.run("manage.py", "loadtracks")
        self.web.run("manage.py", "loaddemoseason")
        self.start_web()
        for machine in self.training:
            self.start_training(machine)
        for machine in self.simulation:
            self.start_simulation(machine, self.processes)
        wait_for(self.listening, "the web machine to listen", timeout=120)

    def start_web(self) -> None:
        self.web.start(
            BIN / "daphne",
            "-b",
            "127.0.0.1",
            "-p",
            str(self.port),
            "--proxy-headers",
            "console.asgi:application",
        )
        # exactly one scheduler, here on the web machine
        self.web.start(BIN / "celery", "-A", "console", "beat")
        # re-scorings, one at a time, beside the checkers that run the same sandbox here
        self.web.start(
            BIN / "celery",
            "-A",
            "console",
            "worker",
            "-Q",
            "rescoring",
            "--hostname",
            f"rescore@{self.web.name}",
            "--concurrency",
            "1",
            "--loglevel",
            "INFO",
        )

    @staticmethod
    def start_training(machine: Machine) -> None:
        machine.start(
            BIN / "celery",
            "-A",
            "console",
            "worker",
            "-Q",
            "training",
            "--hostname",
            f"trainer@{machine.name}",
            "--concurrency",
            "1",
            "--loglevel",
            "INFO",
        )

    @staticmethod
    def start_simulation(machine: Machine, processes: int = 2) -> None:
        machine.start(
            BIN / "celery",
            "-A",
            "console",
            "worker",
            "-Q",
            "simulation",
            "--hostname",
            f"sim@{machine.name}",
            "--concurrency",
            str(processes),
            "--loglevel",
            "INFO",
        )

    def listening(self) -> bool:
        for process in self.web.processes:
            if process.poll() is not None:
                raise RuntimeError(f"the web machine stopped:\n{self.web.log()[-4000:]}")
        try:
            socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
            return True
        except OSError:
            return False

    def stop(self) -> None:
        for machine in self.machines:
            machine.stop()
        self.s3.stop()
        self.redis.stop()
        self.postgres.remove()


def cluster_env(database: str, redis: str, s3: str) -> dict[str, str]:
    """The environment every machine gets: docs/operating.md's variables for several machines."""
    env = {key: value for key, value in os.environ.items() if not key.startswith(OURS)}
    env.update(
        DJANGO_SETTINGS_MODULE="console.settings.prod",
        DJANGO_SECRET_KEY=SECRET_KEY,
        DJANGO_ALLOWED_HOSTS="127.0.0.1,localhost",
        DATABASE_URL=database,
        REDIS_URL=redis,
        PITLANE_S3_BUCKET=BUCKET,
        PITLANE_S3_REGION="us-east-1",
        PITLANE_S3_ENDPOINT_URL=s3,
        AWS_ACCESS_KEY_ID="cluster",
        AWS_SECRET_ACCESS_KEY="cluster",
        PITLANE_HSTS_SECONDS="0",
        PITLANE_TRAINER_THREADS="1",
        PYTHONUNBUFFERED="1",
    )
    return env


def main() -> None:
    parser = argparse.ArgumentParser(description="Pitlane on several machines, on this one.")
    parser.add_argument("--simulation", type=int, default=2, help="simulation machines")
    parser.add_argument("--port", type=int, default=8000)
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="pitlane-cluster-"))
    print(f"Starting PostgreSQL, Redis, S3 and {2 + args.simulation} machines under {folder}")
    cluster = Cluster(folder, simulation=args.simulation, port=args.port, proxied=False)
    try:
        cluster.start()
        print(
            f"Open http://localhost:{args.port}/ (the production settings' cookies are for HTTPS, "
            "which browsers allow on localhost alone). Sign up; add staff on the web machine: "
            f"cd {cluster.web.code} && . ../env && {PYTHON} manage.py createsuperuser"
        )
        print(f"Machines' folders and logs: {folder}/<machine>/. Ctrl-C stops everything.")
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        cluster.stop()
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
