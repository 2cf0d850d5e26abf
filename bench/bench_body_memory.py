"""The web server's memory against a request's body: `python -m bench.bench_body_memory`.

Starts Daphne as `make run` does (``python -m daphne console.asgi:application``, with a Redis of
its own and a scratch database), then posts anonymous multipart bodies, streamed a MiB at a time,
to the sign-in page (limit ``PITLANE_MAX_BODY``, 10 MiB) and to the model import (limit
``PITLANE_MAX_IMPORT_BODY``, 257 MiB): the status, how much of the body had been sent when the
answer came, the seconds to it, Daphne's peak memory during the post over its memory before
(VmHWM, reset through /proc/<pid>/clear_refs before each), and the longest a /healthz asked every
50 ms meanwhile took. ``--tree`` measures another checkout (a worktree of an older commit) the same
way; ``--largest`` leaves out bodies over that many MiB (an unbounded server takes 10 to 15 times
the body).
"""

from __future__ import annotations

import argparse
import os
import select
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from bench.stack import free_port, private_redis, sigterm_exits

MiB = 2**20
PIECE = bytes(MiB)
LOGIN, IMPORT = "/accounts/login/", "/models/import/"
CASES = [  # (path, body size [MiB], sent in chunks with no Content-Length)
    (LOGIN, 10, False),
    (LOGIN, 100, False),
    (LOGIN, 1024, False),
    (LOGIN, 1024, True),
    (IMPORT, 10, False),
    (IMPORT, 100, False),
    (IMPORT, 257, False),
    (IMPORT, 1024, False),
    (IMPORT, 1024, True),
]
HEAD = (
    b'--pitlane\r\nContent-Disposition: form-data; name="archive"; filename="model.tar.gz"\r\n'
    b"Content-Type: application/octet-stream\r\n\r\n"
)
TAIL = b"\r\n--pitlane--\r\n"
HEALTH = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
DAPHNE = [sys.executable, "-m", "daphne", "-b", "127.0.0.1"]  # as console.supervisor starts it


def memory(pid: int, field: str) -> int:
    """[bytes] VmRSS or VmHWM of process ``pid``."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) * 1024
    raise LookupError(field)


def answer_of(connection: socket.socket) -> bytes:
    answer = b""
    try:
        while data := connection.recv(65536):
            answer += data
    except (ConnectionResetError, TimeoutError):
        pass
    return answer


def post(port: int, path: str, size: int, chunked: bool = False) -> tuple[str, int, float]:
    """A multipart body of ``size`` bytes, sent a MiB at a time while no answer has come, with
    its Content-Length or in chunks: (the status line, the bytes sent when it came, the seconds
    to it)."""
    frame = (lambda data: b"%x\r\n%b\r\n" % (len(data), data)) if chunked else (lambda data: data)
    started_at = time.perf_counter()
    with socket.create_connection(("127.0.0.1", port), timeout=120) as connection:
        framing = "Transfer-Encoding: chunked" if chunked else f"Content-Length: {size}"
        connection.sendall(
            f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n{framing}\r\n"
            "Content-Type: multipart/form-data; boundary=pitlane\r\n\r\n".encode()
            + frame(HEAD)
        )
        sent = len(HEAD)
        try:
            while sent < size - len(TAIL) and not select.select([connection], [], [], 0)[0]:
                piece = PIECE[: size - len(TAIL) - sent]
                connection.sendall(frame(piece))
                sent += len(piece)
            if sent == size - len(TAIL):
                connection.sendall(frame(TAIL) + (b"0\r\n\r\n" if chunked else b""))
                sent = size
        except (BrokenPipeError, ConnectionResetError):
            pass
        answer = answer_of(connection)
    status = answer.split(b"\r\n", 1)[0].decode(errors="replace") or "(closed, no answer)"
    return status, sent, time.perf_counter() - started_at


def longest_health_wait(port: int, stop: threading.Event, waits: list[float]) -> None:
    while not stop.is_set():
        started_at = time.perf_counter()
        with socket.create_connection(("127.0.0.1", port), timeout=120) as connection:
            connection.sendall(
                b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
            )
            answer_of(connection)
        waits.append(time.perf_counter() - started_at)
        stop.wait(0.05)


def measure(port: int, pid: int, path: str, size: int, chunked: bool) -> str:
    Path(f"/proc/{pid}/clear_refs").write_text("5")  # VmHWM starts again from VmRSS
    before = memory(pid, "VmRSS")
    stop, waits = threading.Event(), []
    watcher = threading.Thread(target=longest_health_wait, args=(port, stop, waits))
    watcher.start()
    try:
        status, sent, seconds = post(port, path, size, chunked)
    finally:
        stop.set()
        watcher.join()
    growth = (memory(pid, "VmHWM") - before) / MiB
    longest = max(waits, default=0.0)
    body = f"{size / MiB:,.0f} MiB" + (", chunked" if chunked else "")
    return (
        f"| `{path}` | {body} | {status[9:]} | {sent / MiB:,.0f} MiB "
        f"| {seconds:.2f} | {before / MiB:.0f} MiB | +{growth:,.1f} MiB | {longest:.2f} s |"
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tree", type=Path, default=Path(__file__).resolve().parent.parent)
    parser.add_argument("--largest", type=int, default=1024, help="[MiB] the largest body sent")
    chosen = parser.parse_args()
    with (
        sigterm_exits(),
        tempfile.TemporaryDirectory(prefix="pitlane-bench-body-") as var_dir,
        private_redis(var_dir) as redis_url,
    ):
        env = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
        env.update(
            DJANGO_SETTINGS_MODULE="console.settings.dev",
            PITLANE_VAR_DIR=var_dir,
            REDIS_URL=redis_url,
            PYTHONUNBUFFERED="1",
        )
        subprocess.run(
            [sys.executable, "manage.py", "migrate", "--verbosity=0"],
            cwd=chosen.tree,
            env=env,
            check=True,
        )
        port = free_port()
        with open(Path(var_dir) / "daphne.log", "wb") as log:
            daphne = subprocess.Popen(
                [*DAPHNE, "-p", str(port), "console.asgi:application"],
                cwd=chosen.tree,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
        try:
            serve(port, daphne.pid, chosen.largest)
        finally:
            daphne.terminate()
            daphne.wait(60)


def serve(port: int, pid: int, largest: int) -> None:
    deadline = time.monotonic() + 60
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            if time.monotonic() > deadline:
                sys.exit("Daphne did not listen within a minute; see its log.")
            time.sleep(0.2)
    post(port, LOGIN, MiB)  # Django loaded, as after a first request
    print(
        "| path | body | answer | sent by then | seconds | Daphne before | peak growth "
        "| longest /healthz |\n|---|---|---|---|---|---|---|---|"
    )
    for path, mib, chunked in CASES:
        if mib <= largest:
            print(measure(port, pid, path, mib * MiB, chunked), flush=True)


if __name__ == "__main__":
    main()
