"""A limit on the size of request bodies, applied before Django reads them.

Django reads a request's whole body (to a temporary file past a few megabytes) before any view
or middleware can look at it, and Daphne sets no limit, so a client could otherwise make the
server take gigabytes. ``BodyLimit`` wraps the HTTP application: a body whose Content-Length is
over the limit is refused at once, and one sent in chunks as soon as the chunks pass it, with
413 and a sentence saying the limit. Every page takes ``PITLANE_MAX_BODY``; the model import,
the one large upload, takes ``PITLANE_MAX_IMPORT_BODY``. Under Daphne, ``console.daphne_body``
refuses such a body earlier still, as it arrives, before Twisted keeps any more of it; this stays
for any other server.
"""

from __future__ import annotations

from functools import cache
from html import escape

from django.conf import settings
from django.urls import reverse

LARGE_UPLOADS = ("archives:model-import",)  # the pages whose forms upload a model archive


class BodyTooLarge(Exception):
    pass


@cache
def _large_paths() -> frozenset[str]:
    return frozenset(reverse(name) for name in LARGE_UPLOADS)


def limit_for(path: str) -> int:
    """[bytes] the largest body a request to ``path`` may send."""
    if path in _large_paths():
        return settings.PITLANE_MAX_IMPORT_BODY
    return settings.PITLANE_MAX_BODY


class BodyLimit:
    def __init__(self, app) -> None:
        self.app = app

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = limit_for(scope["path"])
        declared = dict(scope.get("headers") or ()).get(b"content-length", b"")
        if declared.isdigit() and int(declared) > limit:
            await _refuse(send, limit)
            return
        received = 0

        async def limited_receive():
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise BodyTooLarge
            return message

        try:
            await self.app(scope, limited_receive, send)
        except BodyTooLarge:  # Django reads the whole body before it answers anything
            await _refuse(send, limit)


def refusal_page(limit: int) -> bytes:
    """The page a 413 answers with: the limit, in words (Daphne's refusal says the same)."""
    size = f"{limit / 2**20:g} MiB" if limit >= 2**20 else f"{limit:,} bytes"
    return (
        "<!doctype html><title>Too large</title><h1>That is too large to send</h1>"
        f"<p>The console takes at most {escape(size)} in one request here. Nothing was saved: "
        "go back and send something smaller.</p>"
    ).encode()


async def _refuse(send, limit: int) -> None:
    body = refusal_page(limit)
    await send(
        {
            "type": "http.response.start",
            "status": 413,
            "headers": [
                (b"content-type", b"text/html; charset=utf-8"),
                (b"content-length", str(len(body)).encode()),
                (b"connection", b"close"),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})
