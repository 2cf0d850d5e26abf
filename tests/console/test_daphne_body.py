"""The real web server (Daphne, as `make run` starts it) keeps a body only to its limit, on disk:
300 MiB sent to a page is refused at once and leaves its memory flat, and a large allowed body
neither swells it nor holds up other requests (console.daphne_body)."""

from __future__ import annotations

import os
import select
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from django.conf import settings
from django.test import Client
from django.urls import reverse

from tests.helpers.accounts import racer
from tests.services import ServiceProcess, daphne_started, wait_for

pytestmark = pytest.mark.slow

MiB = 2**20
PIECE = bytes(MiB)  # the test's whole body in memory: one piece, sent again and again


class WebServer:
    def __init__(self, process: ServiceProcess, port: int) -> None:
        self.process = process
        self.port = port

    def memory(self, field: str) -> int:
        """[bytes] VmRSS (now) or VmHWM (the peak so far) of the Daphne process."""
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) * 1024
        raise LookupError(field)


@pytest.fixture(scope="module")
def web_server(test_database, logs_dir) -> Iterator[WebServer]:
    """A Daphne of this module's own (the suite's ``daphne_server``, but its process is needed)."""
    process, port = daphne_started(test_database, logs_dir / "daphne-body.log")
    try:
        server = WebServer(process, port)
        get(server, "/healthz")  # Django loaded, the first request's imports done
        yield server
    finally:
        process.stop()


def get(server: WebServer, path: str) -> bytes:
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as connection:
        request = f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
        connection.sendall(request.encode())
        return read_all(connection)


def read_all(connection: socket.socket) -> bytes:
    answer = b""
    try:
        while data := connection.recv(65536):
            answer += data
    except ConnectionResetError:
        pass
    return answer


def post(
    server: WebServer, path: str, size: int, *, chunked: bool = False, heed: bool = True
) -> tuple[bytes, int]:
    """POST ``size`` bytes to ``path`` a MiB at a time, with its Content-Length or in chunks,
    stopping when an answer comes (unless not ``heed``, as an attacker would not); (the answer,
    the bytes sent by the time it came)."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=30) as connection:
        framing = "Transfer-Encoding: chunked" if chunked else f"Content-Length: {size}"
        connection.sendall(
            f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n{framing}\r\n"
            "Content-Type: multipart/form-data; boundary=pitlane\r\n\r\n".encode()
        )
        sent = 0
        try:
            while sent < size and not (heed and select.select([connection], [], [], 0)[0]):
                piece = PIECE[: size - sent]
                connection.sendall(b"%x\r\n%b\r\n" % (len(piece), piece) if chunked else piece)
                sent += len(piece)
            if chunked and sent == size:
                connection.sendall(b"0\r\n\r\n")
        except (BrokenPipeError, ConnectionResetError):
            pass  # the server answered and closed: its answer is still to read
        return read_all(connection), sent


def test_300_mib_to_a_page_is_refused_at_once_and_the_server_stays_small(web_server):
    before = web_server.memory("VmHWM")
    started = time.monotonic()
    answer, sent = post(web_server, reverse("login"), 300 * MiB)
    assert answer.startswith(b"HTTP/1.1 413 ")
    assert b"at most 10 MiB" in answer
    assert time.monotonic() - started < 5
    assert sent < 100 * MiB  # answered long before the body was sent
    assert web_server.memory("VmHWM") - before < 50 * MiB


def test_a_body_in_chunks_is_refused_once_it_passes_the_limit(web_server):
    before = web_server.memory("VmHWM")
    answer, sent = post(web_server, reverse("login"), 300 * MiB, chunked=True)
    assert answer.startswith(b"HTTP/1.1 413 ")
    assert b"Nothing was saved" in answer
    assert 10 * MiB <= sent < 100 * MiB
    assert web_server.memory("VmHWM") - before < 50 * MiB


def health_waits_while(server: WebServer, action: Callable[[], object]) -> tuple[object, list]:
    """What ``action`` returns, and the seconds each /healthz asked meanwhile took to answer."""
    outcome = {}
    worker = threading.Thread(target=lambda: outcome.setdefault("value", action()))
    worker.start()
    waits = []
    while worker.is_alive():
        started = time.monotonic()
        assert get(server, "/healthz").startswith(b"HTTP/1.1 ")
        waits.append(time.monotonic() - started)
        time.sleep(0.05)
    worker.join()
    return outcome["value"], waits


def test_a_client_that_asks_to_continue_is_refused_before_it_sends(web_server):
    """Expect: 100-continue with a length over the limit: 413 at once, never "100 Continue"."""
    with socket.create_connection(("127.0.0.1", web_server.port), timeout=30) as connection:
        connection.sendall(
            f"POST {reverse('login')} HTTP/1.1\r\nHost: 127.0.0.1\r\nExpect: 100-continue\r\n"
            f"Content-Length: {300 * MiB}\r\n\r\n".encode()
        )
        answer = read_all(connection)
    assert answer.startswith(b"HTTP/1.1 413 ")
    assert b"100 Continue" not in answer


def test_a_client_that_sends_on_after_the_413_neither_swells_nor_holds_the_server(web_server):
    """The rest of a refused body is read and dropped (for 2 s, then the connection closed)."""
    before = web_server.memory("VmHWM")
    (answer, _), waits = health_waits_while(
        web_server, lambda: post(web_server, reverse("login"), 300 * MiB, heed=False)
    )
    assert answer == b"" or answer.startswith(b"HTTP/1.1 413 ")  # unread when the reset came
    assert max(waits) < 1.0
    assert web_server.memory("VmHWM") - before < 50 * MiB


def test_the_largest_import_reaches_django_and_the_server_stays_small_and_answers(web_server):
    """An allowed body of the import's limit (257 MiB) is read to disk and handed to Django (which
    refuses a POST with no CSRF cookie, after reading it); /healthz answers within a second
    throughout, and the server's peak memory grows by less than 50 MiB."""
    before = web_server.memory("VmHWM")
    (answer, sent), waits = health_waits_while(
        web_server, lambda: post(web_server, reverse("archives:model-import"), 257 * MiB)
    )
    assert answer.startswith(b"HTTP/1.1 403 ")  # Django's CSRF refusal: no 413
    assert sent == 257 * MiB
    assert len(waits) > 3 and max(waits) < 1.0
    assert web_server.memory("VmHWM") - before < 50 * MiB


@pytest.mark.django_db(transaction=True)  # the sign-in page reads the accounts' table
def test_a_multipart_body_within_the_limit_reaches_django_whole(web_server):
    """The CSRF token comes last, after 8 MiB of a file: the sign-in page accepts it (and says the
    password is wrong) only if the whole body arrived, through Django's own upload handlers."""
    secret = "p" * 32  # a CSRF cookie's secret, which the form may send as it is
    body = (
        b'--pitlane\r\nContent-Disposition: form-data; name="file"; filename="a.bin"\r\n\r\n'
        + bytes(8 * MiB)
        + b'\r\n--pitlane\r\nContent-Disposition: form-data; name="username"\r\n\r\nnobody'
        + b'\r\n--pitlane\r\nContent-Disposition: form-data; name="password"\r\n\r\nwrong'
        + b'\r\n--pitlane\r\nContent-Disposition: form-data; name="csrfmiddlewaretoken"\r\n\r\n'
        + secret.encode()
        + b"\r\n--pitlane--\r\n"
    )
    with socket.create_connection(("127.0.0.1", web_server.port), timeout=30) as connection:
        connection.sendall(
            f"POST {reverse('login')} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n"
            f"Cookie: csrftoken={secret}\r\nContent-Length: {len(body)}\r\n"
            "Content-Type: multipart/form-data; boundary=pitlane\r\n\r\n".encode()
            + body
        )
        answer = read_all(connection)
    assert answer.startswith(b"HTTP/1.1 200 "), answer[:300]


@pytest.mark.django_db(transaction=True)
def test_a_websocket_still_opens_through_the_request(web_server):
    """Daphne's request hands a websocket's handshake to its websocket protocol as before: a
    staff member's probe is accepted."""
    client = Client()
    client.force_login(racer("marshal", is_staff=True))
    session = client.cookies[settings.SESSION_COOKIE_NAME].value
    with socket.create_connection(("127.0.0.1", web_server.port), timeout=30) as connection:
        connection.sendall(
            b"GET /ws/system/probe/ HTTP/1.1\r\nHost: 127.0.0.1\r\nOrigin: http://127.0.0.1\r\n"
            b"Upgrade: websocket\r\nConnection: Upgrade\r\n"
            b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
            + f"Cookie: {settings.SESSION_COOKIE_NAME}={session}\r\n\r\n".encode()
        )
        head = connection.recv(4096)
    assert head.startswith(b"HTTP/1.1 101 "), head


@pytest.fixture(scope="module")
def capped_server(request, test_database, logs_dir) -> Iterator[WebServer]:
    """A Daphne that takes 4 MiB of bodies at once, each within 60 s, or the deadline a test
    gives as its parameter (the tests that hold bodies open meanwhile keep 60, as the suite may
    be very busy)."""
    process, port = daphne_started(
        test_database,
        logs_dir / "daphne-capped.log",
        {
            "PITLANE_BODIES_IN_FLIGHT_MAX": str(4 * MiB),
            "PITLANE_BODY_DEADLINE": str(getattr(request, "param", 60)),
            "PITLANE_BODY_RATE": str(2**30),
        },
    )
    try:
        server = WebServer(process, port)
        get(server, "/healthz")
        yield server
    finally:
        process.stop()


def spooled(server: WebServer) -> list[int]:
    """[bytes] each body file the server holds open in FILE_UPLOAD_TEMP_DIR (anonymous files)."""
    sizes = []
    for fd in Path(f"/proc/{server.process.pid}/fd").iterdir():
        try:
            if os.readlink(fd).startswith(f"{settings.FILE_UPLOAD_TEMP_DIR}/"):
                sizes.append(fd.stat().st_size)
        except FileNotFoundError:
            pass  # closed meanwhile
    return sorted(sizes)


def begun(server: WebServer, size: int, sent: int, *, last: int = 0) -> socket.socket:
    """A connection that declares a body of ``size`` bytes to the sign-in page, and ``sent`` of
    them; the ``last`` of those a moment after the rest, as a read of its own (a busy machine's
    reads end a MiB with a piece of a few kB as often as not)."""
    connection = socket.create_connection(("127.0.0.1", server.port), timeout=30)
    connection.sendall(
        f"POST {reverse('login')} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n"
        f"Content-Length: {size}\r\n"
        "Content-Type: multipart/form-data; boundary=pitlane\r\n\r\n".encode()
        + bytes(sent - last)
    )
    if last:
        time.sleep(0.2)
        connection.sendall(bytes(last))
    return connection


def test_bodies_past_the_in_flight_cap_are_refused_and_nothing_more_is_spooled(capped_server):
    first, second = begun(capped_server, 2 * MiB, MiB), begun(capped_server, 2 * MiB, MiB)
    try:
        wait_for(lambda: spooled(capped_server) == [MiB, MiB], "two bodies half sent", 30)
        for chunked in (False, True):
            answer, _ = post(capped_server, reverse("login"), 2 * MiB, chunked=chunked)
            assert answer.startswith(b"HTTP/1.1 503 "), answer[:200]
            assert b"Retry-After: 30\r\n" in answer
            assert b"try again in a minute" in answer
        assert spooled(capped_server) == [MiB, MiB]  # the refused bodies kept nothing
        first.sendall(bytes(MiB))
        assert not read_all(first).startswith(b"HTTP/1.1 503 ")  # Django's answer
        answer, _ = post(capped_server, reverse("login"), 2 * MiB)  # the first's room is free
        assert answer.startswith(b"HTTP/1.1 ") and not answer.startswith(b"HTTP/1.1 503 ")
    finally:
        first.close()
        second.close()


@pytest.mark.parametrize("capped_server", [6], indirect=True)
def test_a_body_that_stalls_past_its_deadline_is_dropped_with_its_file(capped_server):
    # Its first MiB ends with a piece of 1,000 bytes: the spool holds every byte received, none
    # left in a write buffer (where the suite's runs on 2 cores waited up to 19 s for the last
    # few kB, which a busy machine's reads left in a piece of their own).
    started = time.monotonic()
    with begun(capped_server, 3 * MiB, MiB, last=1000) as connection:
        wait_for(lambda: spooled(capped_server) == [MiB], "the body's first MiB", 5)
        answer = read_all(connection)  # nothing more sent: the server answers when 6 s are up
    assert answer.startswith(b"HTTP/1.1 408 "), answer[:200]
    assert 5.5 < time.monotonic() - started < 30
    wait_for(lambda: spooled(capped_server) == [], "the body's file to go", 5)
    answer, _ = post(capped_server, reverse("login"), 3 * MiB)  # its 3 MiB no longer counted
    assert not answer.startswith(b"HTTP/1.1 503 ")


def test_an_empty_body_in_chunks_opens_no_file(capped_server):
    with socket.create_connection(("127.0.0.1", capped_server.port), timeout=30) as connection:
        connection.sendall(
            f"POST {reverse('login')} HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            "Transfer-Encoding: chunked\r\n\r\n".encode()
        )
        time.sleep(0.3)
        assert spooled(capped_server) == []
        connection.sendall(b"0\r\n\r\n")
        assert connection.recv(4096).startswith(b"HTTP/1.1 ")
