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
"""

from __future__ import annotations

import asyncio
import io
import tempfile
from urllib.parse import unquote

from daphne import http_protocol
from django.conf import settings

from console.bodylimit import limit_for, refusal_page

EXTENSION = "pitlane.body_file"  # scope["extensions"][EXTENSION] = {"file": the body}
PIECE = 1 << 20  # [bytes] of the body in one http.request message
IN_MEMORY = 100_000  # [bytes] a declared body under this is kept in memory (Twisted's own figure)
LINGER = 2.0  # [s] after a 413, the rest of the body is read and dropped, then the socket closed


def _discard(data: bytes) -> None:
    pass


class BoundedBodyRequest(http_protocol.WebRequest):
    """Daphne's request, which keeps a body only up to its path's limit, on disk past 100 kB."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs["parsePOSTFormSubmission"] = False
        self._refused = False
        self._received = 0
        self._limit = 0
        self._body: io.IOBase | None = None
        super().__init__(*args, **kwargs)
        self.server = _ServerForRequest(self.server, self)

    def gotLength(self, length: int | None) -> None:
        # The target of the request line; HTTPChannel.lineReceived keeps it before the headers.
        target = getattr(self.channel, "_path", b"").split(b"?", 1)[0]
        self._limit = limit_for(unquote(target.decode("ascii", "replace")))
        if length is not None and length > self._limit:
            self._refuse()
        elif length is not None and length < IN_MEMORY:
            self.content = io.BytesIO()
        else:
            # closed by the request (as Twisted closes content) or, handed over, by BodyFromFile
            self.content = tempfile.TemporaryFile(dir=settings.FILE_UPLOAD_TEMP_DIR)  # noqa: SIM115

    def handleContentChunk(self, data: bytes) -> None:
        if self._refused:
            return
        self._received += len(data)
        if self._received > self._limit:
            self._refuse()
        else:
            self.content.write(data)

    def requestReceived(self, command: bytes, path: bytes, version: bytes) -> None:
        if self._refused:
            return
        self._body, self.content = self.content, io.BytesIO()
        self._body.seek(0)
        super().requestReceived(command, path, version)

    def finish(self) -> None:
        self._close_body()
        super().finish()

    def connectionLost(self, reason) -> None:
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

    def _refuse(self) -> None:
        """Answer 413 at once; read the rest only to drop it, so that the client can read the
        answer (a socket closed on unread data resets, and may take the answer with it)."""
        self._refused = True
        if self.content is not None:
            self.content.close()
            self.content = None
        # allHeadersReceived would send "100 Continue" after the answer
        self.requestHeaders.removeHeader(b"expect")
        page = refusal_page(self._limit)
        head = (
            "HTTP/1.1 413 Content Too Large\r\n"
            "Content-Type: text/html; charset=utf-8\r\n"
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
                "status": 413,
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
