"""A file sent to a browser whole, or the one byte range it asks for (RFC 9110 section 14).

A video element seeks by asking for ``Range: bytes=<offset>-``: a server that answers 200 with the
whole body leaves the video unseekable (``seekable`` is [0, 0], a seek snaps back to the start).
``file_response`` answers one range with 206, a range beyond the end with 416, and anything else
(no range, one it cannot read, several ranges) with the whole file, as RFC 9110 allows; the file is
read in chunks as it is sent, never whole: under Daphne through an asynchronous iterator, since
Django's ASGI handler reads a synchronous one to its end before it sends a byte.
"""

from __future__ import annotations

import io
import re
from collections.abc import AsyncIterator
from typing import IO

from asgiref.sync import sync_to_async
from django.core.handlers.asgi import ASGIRequest
from django.http import FileResponse, HttpRequest, HttpResponse

CHUNK = 64 * 1024  # [bytes] read from the file per write to the client
# One range: first-last, first- (to the end), or -suffix (the last bytes). The unit is
# case-insensitive (RFC 9110 section 14.1). Positions of up to 18 digits (an exabyte): a longer
# one is no file's, and int() of thousands of digits raises; such a header reads as no range.
ONE_RANGE = re.compile(r"\s*bytes\s*=\s*(\d{0,18})\s*-\s*(\d{0,18})\s*", re.IGNORECASE)


class Unsatisfiable(Exception):
    """The range asked for starts at or after the end of the file."""


def byte_range(header: str, size: int) -> tuple[int, int] | None:
    """The first and last byte (inclusive) that ``header`` asks for of a file of ``size`` bytes;
    None for the whole file (no range, one that cannot be read, several). Raises Unsatisfiable
    for a range no byte of the file is in."""
    found = ONE_RANGE.fullmatch(header)
    if not found or found.group(1) == found.group(2) == "":
        return None
    first, last = found.group(1), found.group(2)
    if first == "":  # the last ``last`` bytes
        suffix = int(last)
        if suffix == 0 or size == 0:
            raise Unsatisfiable
        return max(size - suffix, 0), size - 1
    start = int(first)
    if last and int(last) < start:
        return None  # not a valid range: ignored (RFC 9110 section 14.1.1)
    if start >= size:
        raise Unsatisfiable
    return start, min(int(last), size - 1) if last else size - 1


class _Slice:
    """``length`` bytes of ``file`` from where it stands, read as the response is sent (no
    ``tell`` or ``seek``: FileResponse then leaves Content-Length to the caller)."""

    def __init__(self, file: IO[bytes], length: int) -> None:
        self._file = file
        self._left = length

    def read(self, size: int = -1) -> bytes:
        wanted = self._left if size < 0 else min(size, self._left)
        data = self._file.read(wanted) if wanted else b""
        self._left -= len(data)
        return data

    def close(self) -> None:
        self._file.close()


def file_response(
    request: HttpRequest,
    file: IO[bytes],
    *,
    filename: str,
    attachment: bool,
    content_type: str | None = None,
    ranges: bool = True,
) -> HttpResponse:
    """``file`` (open, seekable, binary; closed once sent) as the answer to ``request``: 206 with
    the one byte range it asks for, 416 for a range past the end, else 200 with the whole file;
    every answer says ``Accept-Ranges: bytes``. A HEAD request gets the same headers and no
    body. The caller has checked the racer's right to the file.

    ``ranges=False`` for a file built anew for each request (its bytes differ from one to the
    next, so a download resumed from a range would splice two files): always the whole file, and
    ``Accept-Ranges: none``."""
    size = file.seek(0, io.SEEK_END)
    # A validator in If-Range cannot match: these answers send none (no ETag, no date).
    asked = ranges and "If-Range" not in request.headers
    header = request.headers.get("Range", "") if asked else ""
    try:
        wanted = byte_range(header, size)
    except Unsatisfiable:
        file.close()
        refused = HttpResponse(status=416)
        refused["Content-Range"] = f"bytes */{size}"
        refused["Accept-Ranges"] = "bytes"
        return refused
    start, end = wanted or (0, size - 1)
    file.seek(start)
    piece = _Slice(file, end - start + 1)
    response = FileResponse(
        piece,
        status=206 if wanted else 200,
        as_attachment=attachment,
        filename=filename,
        content_type=content_type,
    )
    response.block_size = CHUNK
    response["Content-Length"] = str(end - start + 1)
    response["Accept-Ranges"] = "bytes" if ranges else "none"
    if wanted:
        response["Content-Range"] = f"bytes {start}-{end}/{size}"
    if request.method == "HEAD":
        headers = dict(response.items())
        response.close()
        return HttpResponse(status=response.status_code, headers=headers)
    if isinstance(request, ASGIRequest):  # the file is still closed with the response
        response.streaming_content = _chunks(piece)
    return response


async def _chunks(piece: _Slice) -> AsyncIterator[bytes]:
    """``piece`` in chunks of ``CHUNK`` bytes, each read in a thread (off the event loop)."""
    read = sync_to_async(piece.read, thread_sensitive=False)
    while chunk := await read(CHUNK):
        yield chunk
