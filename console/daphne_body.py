"""Daphne reads a request's body to its limit, onto disk, and hands it over a piece at a time.

Pinned: daphne 4.2.3 and Twisted 26.10.0 (``requirements/run.txt``). As they are, one request
could take the web server's memory and its reactor before ``console.bodylimit`` saw it:

1. ``twisted/web/http.py``, ``Request.requestReceived`` (the ``_parsePOSTFormSubmission`` branch):
   a multipart or URL-encoded POST is read whole into memory and parsed into ``request.args``, on
   the reactor thread. Daphne never reads ``args``; Django parses the body itself.
2. ``Request.gotLength`` and ``Request.handleContentChunk``: the whole body is kept (a BytesIO under
   100,000 bytes, else a temporary file) before ``requestReceived`` runs, with no limit.
3. ``daphne/http_protocol.py``, the ``while True`` loop that ends ``WebRequest.process``: the whole
   body is read from that file into the application's queue at once, in 8 KiB messages.

``BoundedBodyRequest``, the request Daphne's ``HTTPFactory`` makes once ``install`` has run, turns
off 1 (``parsePOSTFormSubmission=False``); for 2 it takes the path's limit
(``bodylimit.limit_for``) and answers 413 in the same words as soon as the declared length or the
bytes received pass it, keeping nothing more; a body within it goes to a temporary file
(``FILE_UPLOAD_TEMP_DIR``). For 3 it gives Daphne's loop an empty body and the file to the
application, in the scope's ``pitlane.body_file`` extension, which ``BodyFromFile`` reads a piece
(``PIECE``) at a time as the application asks: Django then writes it to its own spooled file
(``FILE_UPLOAD_MAX_MEMORY_SIZE``). The tests in ``tests/console/test_daphne_body.py`` hold these
versions to it. HTTP/1.1 only: Daphne speaks HTTP/2 only with Twisted's ``http2`` extra, which is
not installed (an H2 stream has no request line of its own, so every path would get the default
limit).

What bounds the disk: the bodies being received by the process together, counted here
(``_in_flight``; a declared length reserved whole when the headers arrive, a chunked body as its
bytes arrive, released when the request finishes or its connection drops). A body over
``IN_MEMORY`` that would take the count past ``PITLANE_BODIES_IN_FLIGHT_MAX`` is answered 503
(``Retry-After``) before any of it is kept; smaller ones, kept in memory, are never refused, so
that sign-in and other forms go on working while large uploads fill the count. And a deadline per
body, from its headers (Twisted's idle timeout restarts with every byte, and Daphne sets none): the
longer of ``PITLANE_BODY_DEADLINE`` and the body's length (its path's limit if sent in chunks) at
``PITLANE_BODY_RATE``: 30 s for a page's 10 MiB, 8.6 min for the import's 257 MiB at 512 KiB/s (a
4 Mbit/s uplink), so a client that trickles a byte at a time is dropped, and its file with it. The
file is opened only once a body passes ``IN_MEMORY``.
"""

from __future__ import annotations

import asyncio
import io
import tempfile
from urllib.parse import unquote

from daphne import http_protocol
from django.conf import settings

from console.bodylimit import limit_for, refusal

EXTENSION = "pitlane.body_file"  # scope["extensions"][EXTENSION] = {"file": the body}
PIECE = 1 << 20  # [bytes] of the body in one http.request message
IN_MEMORY = 100_000  # [bytes] a declared body under this is kept in memory (Twisted's own figure)
LINGER = 2.0  # [s] after a refusal, the rest of the body is read and dropped, then closed
RETRY_AFTER = 30  # [s] a 503 for too many bodies at once asks the client to wait this long
BUSY_PAGE = (
    b"<!doctype html><title>Busy</title><h1>The console is receiving too much at once</h1>"
    b"<p>Nothing was saved: try again in a minute.</p>"
)
SLOW_PAGE = (
    b"<!doctype html><title>Too slow</title><h1>That took too long to send</h1>"
    b"<p>Nothing was saved: try again, on a faster connection if you can.</p>"
)
_in_flight = 0  # [bytes] of the bodies this process is receiving (reserved or received) together


def _discard(data: bytes) -> None:
    pass


class BoundedBodyRequest(http_protocol.WebRequest):
    """Daphne's request, which keeps a body only up to its path's limit, on disk past 100 kB."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs["parsePOSTFormSubmission"] = False
        self._refused = False
        self._received = 0
        self._limit = 0
        self._reserved = 0  # [bytes] of _in_flight this request holds
        self._deadline = None  # the DelayedCall that drops a body still arriving
        self._body: io.IOBase | None = None
        super().__init__(*args, **kwargs)
        self.server = _ServerForRequest(self.server, self)

    def gotLength(self, length: int | None) -> None:
        # The target of the request line; HTTPChannel.lineReceived keeps it before the headers.
        target = getattr(self.channel, "_path", b"").split(b"?", 1)[0]
        self._target = unquote(target.decode("ascii", "replace"))
        self._limit = limit_for(self._target)
        self.content = io.BytesIO()  # to a file once past IN_MEMORY (handleContentChunk)
        if length is not None and length > self._limit:
            self._refuse_too_large()
        elif length is not None and not self._reserve(length):
            self._refuse_busy()
        elif length != 0:
            seconds = max(
                settings.PITLANE_BODY_DEADLINE, (length or self._limit) / settings.PITLANE_BODY_RATE
            )
            self._deadline = self.channel.callLater(seconds, self._too_slow)

    def _reserve(self, size: int) -> bool:
        """Count ``size`` more bytes in flight for this request, unless that passes the maximum
        for a body kept on disk (one within IN_MEMORY is always counted, never refused)."""
        global _in_flight
        if (
            max(size, self._received) > IN_MEMORY
            and _in_flight + size > settings.PITLANE_BODIES_IN_FLIGHT_MAX
        ):
            return False
        _in_flight += size
        self._reserved += size
        return True

    def _release(self) -> None:
        global _in_flight
        _in_flight -= self._reserved
        self._reserved = 0
        if self._deadline is not None and self._deadline.active():
            self._deadline.cancel()
        self._deadline = None

    def handleContentChunk(self, data: bytes) -> None:
        if self._refused:
            return
        self._received += len(data)
        if self._received > self._limit:
            self._refuse_too_large()
            return
        if self._received > self._reserved and not self._reserve(self._received - self._reserved):
            self._refuse_busy()
            return
        if self._received > IN_MEMORY and isinstance(self.content, io.BytesIO):
            # closed by the request (as Twisted closes content) or, handed over, by BodyFromFile
            spool = tempfile.TemporaryFile(dir=settings.FILE_UPLOAD_TEMP_DIR)  # noqa: SIM115
            spool.write(self.content.getvalue())
            self.content = spool
        self.content.write(data)
        if not isinstance(self.content, io.BytesIO):
            self.content.flush()  # every byte received is on disk, none held in a write buffer

    def requestReceived(self, command: bytes, path: bytes, version: bytes) -> None:
        if self._deadline is not None and self._deadline.active():
            self._deadline.cancel()  # the whole body is here (the count is kept till finish)
        self._deadline = None
        if self._refused:
            return
        self._body, self.content = self.content, io.BytesIO()
        self._body.seek(0)
        super().requestReceived(command, path, version)

    def finish(self) -> None:
        self._release()
        self._close_body()
        super().finish()

    def connectionLost(self, reason) -> None:
        self._release()
        self._close_body()
        super().connectionLost(reason)

    def _close_body(self) -> None:
        if self._body is not None:  # never handed to an application (Daphne answered itself)
            self._body.close()
            self._body = None

    def handed_over(self) -> io.IOBase | None:
        """The body, for the application; from then on the application closes it."""
        body, self._body = self._body, None
        return body

    def _refuse_too_large(self) -> None:
        content_type, page = refusal(self._limit, self._target)
        self._refuse(413, "Content Too Large", page, content_type=content_type)

    def _refuse_busy(self) -> None:
        self._refuse(503, "Service Unavailable", BUSY_PAGE, f"Retry-After: {RETRY_AFTER}\r\n")

    def _too_slow(self) -> None:
        """The body's deadline passed before the whole of it arrived: drop it and its file."""
        self._deadline = None
        if not self._refused:
            self._refuse(408, "Request Timeout", SLOW_PAGE)

    def _refuse(
        self,
        status: int,
        reason: str,
        page: bytes,
        extra: str = "",
        content_type: str = "text/html; charset=utf-8",
    ) -> None:
        """Answer at once; read the rest only to drop it, so that the client can read the
        answer (a socket closed on unread data resets, and may take the answer with it)."""
        self._refused = True
        self._release()
        if self.content is not None:
            self.content.close()
            self.content = None
        # allHeadersReceived would send "100 Continue" after the answer
        self.requestHeaders.removeHeader(b"expect")
        head = (
            f"HTTP/1.1 {status} {reason}\r\n{extra}"
            f"Content-Type: {content_type}\r\n"
            f"Content-Length: {len(page)}\r\nConnection: close\r\n\r\n"
        )
        channel, transport = self.channel, self.channel.transport
        channel.dataReceived = _discard
        transport.write(head.encode() + page)
        getattr(transport, "loseWriteConnection", transport.loseConnection)()
        channel.callLater(LINGER, transport.abortConnection)
        self.server.log_action(  # in Daphne's access log, as the answers it sends are
            "http",
            "complete",
            {
                "path": getattr(channel, "_path", b"").decode("ascii", "replace"),
                "status": status,
                "method": getattr(channel, "_command", b"").decode("ascii", "replace"),
                "client": f"{getattr(self.client, 'host', '')}:{getattr(self.client, 'port', '')}",
                "time_taken": 0.0,
                "size": len(page),
            },
        )


class _ServerForRequest:
    """Daphne's server as one request sees it: the application it creates gets the body's file."""

    def __init__(self, server, request: BoundedBodyRequest) -> None:
        self._server = server
        self._request = request

    def __getattr__(self, name: str):
        return getattr(self._server, name)

    def create_application(self, protocol, scope: dict):
        body = self._request.handed_over()
        if body is not None:
            scope["extensions"] = {**scope.get("extensions", {}), EXTENSION: {"file": body}}
        return self._server.create_application(protocol, scope)


class BodyFromFile:
    """ASGI middleware: a body Daphne kept in a file (``BoundedBodyRequest``) is read from it a
    piece at a time, as the application asks; then Daphne's own last message (an empty body)."""

    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send) -> None:
        body = scope.get("extensions", {}).get(EXTENSION)
        if body is None:
            await self.app(scope, receive, send)
            return
        file = body["file"]

        async def receive_piece():
            if not file.closed:
                piece = file.read(PIECE)
                if piece:
                    await asyncio.sleep(0)  # the reactor serves others between pieces
                    return {"type": "http.request", "body": piece, "more_body": True}
                file.close()
            return await receive()

        try:
            await self.app(scope, receive_piece, send)
        finally:
            file.close()


def install() -> None:
    """Make Daphne's HTTPFactory build ``BoundedBodyRequest``s (its ``buildProtocol`` reads the
    module's ``WebRequest``); Daphne loads the application, and so this, before it listens."""
    http_protocol.WebRequest = BoundedBodyRequest
