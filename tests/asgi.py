"""Requests to the whole ASGI application (``console.asgi``), as Daphne hands them over: the body
limit, the async middleware chain and the views, with no server in between."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from asgiref.testing import ApplicationCommunicator


@dataclass
class Response:
    status: int
    headers: dict[str, str]  # names in lower case
    body: bytes

    @property
    def text(self) -> str:
        return self.body.decode()


async def request(
    method: str,
    path: str,
    headers: dict[str, str],
    chunks: Sequence[bytes] = (b"",),
    timeout: float = 10,
) -> Response:
    """The response to ``method path``, its body sent in ``chunks``; ``timeout`` bounds each wait
    for a part of the answer."""
    from console.asgi import application

    scope = {
        "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": method,
        "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"",
        "root_path": "", "headers": [(k.encode(), v.encode()) for k, v in headers.items()],
        "client": ("127.0.0.1", 5000), "server": ("127.0.0.1", 8000),
    }  # fmt: skip
    communicator = ApplicationCommunicator(application, scope)
    for n, chunk in enumerate(chunks):
        await communicator.send_input(
            {"type": "http.request", "body": chunk, "more_body": n < len(chunks) - 1}
        )
    start = await communicator.receive_output(timeout=timeout)
    body = b""
    while True:
        message = await communicator.receive_output(timeout=timeout)
        body += message.get("body", b"")
        if not message.get("more_body"):
            break
    await communicator.wait(timeout=10)
    received = {k.decode().lower(): v.decode() for k, v in start.get("headers", [])}
    return Response(start["status"], received, body)
