"""A limit on the size of request bodies, applied before Django reads them.

Django reads a request's whole body (to a temporary file past a few megabytes) before any view or
middleware can look at it, and Daphne sets no limit, so a client could otherwise make the server
take gigabytes. ``BodyLimit`` wraps the HTTP application: a body whose Content-Length is over the
limit is refused at once, and one sent in chunks as soon as the chunks pass it, with 413 and a
sentence saying the limit. Every page takes ``PITLANE_MAX_BODY``; the model import (its page's and
the API's), the one large upload, takes ``PITLANE_MAX_IMPORT_BODY``. Under Daphne,
``console.daphne_body`` refuses such a body earlier still, as it arrives, before Twisted keeps any
more of it; this stays for any other server.
"""

from __future__ import annotations

import json
from functools import cache
from html import escape

from django.conf import settings
from django.urls import reverse

# The pages whose forms upload a model archive, and the API's import.
LARGE_UPLOADS = ("archives:model-import", "api-v1:model-import")
API_PATHS = "/api/v1/"  # whose refusals are JSON, as the API's are


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
            await _refuse(send, limit, scope["path"])
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
            await _refuse(send, limit, scope["path"])


def refusal(limit: int, path: str) -> tuple[str, bytes]:
    """What a 413 answers with (Daphne's refusal says the same): its content type and body, the
    limit in words; in the API's JSON shape under ``/api/v1/``, else a page."""
    size = f"{limit / 2**20:g} MiB" if limit >= 2**20 else f"{limit:,} bytes"
    if path.startswith(API_PATHS):
        words = f"The console takes at most {size} in one request here: send something smaller."
        return "application/json", json.dumps({"code": "too_large", "message": words}).encode()
    page = (
        "<!doctype html><title>Too large</title><h1>That is too large to send</h1>"
        f"<p>The console takes at most {escape(size)} in one request here. Nothing was saved: "
        "go back and send something smaller.</p>"
    )
    return "text/html; charset=utf-8", page.encode()


async def _refuse(send, limit: int, path: str) -> None:
    content_type, body = refusal(limit, path)
    await send(
        {
            "type": "http.response.start",
            "status": 413,
            "headers": [
                (b"content-type", content_type.encode()),
                (b"content-length", str(len(body)).encode()),
                (b"connection", b"close"),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})
