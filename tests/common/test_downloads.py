"""Which bytes a Range header asks for (RFC 9110 section 14): one range is answered, a range past
the end is refused, and anything else gets the whole file."""

import asyncio
import io

import pytest
from django.test import AsyncRequestFactory, RequestFactory

from common.downloads import Unsatisfiable, byte_range, file_response


@pytest.mark.parametrize(
    ("header", "wanted"),
    [
        ("bytes=0-9", (0, 9)),
        ("bytes=10-", (10, 99)),
        ("bytes=-10", (90, 99)),
        ("bytes=-500", (0, 99)),  # a suffix longer than the file: all of it
        ("bytes=90-500", (90, 99)),  # a last byte past the end: up to the end
        ("Bytes = 5 - 6", (5, 6)),
    ],
)
def test_it_reads_the_one_range_asked_for(header, wanted):
    assert byte_range(header, 100) == wanted


@pytest.mark.parametrize(
    "header",
    [
        *["", "bytes=", "bytes=-", "bytes=9-3", "items=0-9", "bytes=0-9,20-29", "bytes=a-b"],
        f"bytes={'9' * 5000}-",  # no file's position, and int() of it would raise
        f"bytes=0-{'9' * 19}",
    ],
)
def test_it_answers_the_whole_file_for_no_range_an_unreadable_one_or_several(header):
    assert byte_range(header, 100) is None


@pytest.mark.parametrize(
    ("header", "size"), [("bytes=100-", 100), ("bytes=-0", 100), ("bytes=-5", 0)]
)
def test_it_refuses_a_range_that_no_byte_of_the_file_is_in(header, size):
    with pytest.raises(Unsatisfiable):
        byte_range(header, size)


def _collected(response) -> bytes:
    async def collect() -> bytes:
        return b"".join([chunk async for chunk in response.streaming_content])

    return asyncio.run(collect())


def test_under_daphne_the_file_is_read_as_it_is_sent_not_before():
    """Django's ASGI handler would read a synchronous iterator to its end before sending a byte:
    under Daphne the range comes as an asynchronous one, read chunk by chunk."""
    data = bytes(range(256)) * 1024  # 256 KiB: several chunks
    file = io.BytesIO(data)
    request = AsyncRequestFactory().get("/video", headers={"Range": "bytes=1000-"})
    response = file_response(request, file, filename="v.webm", attachment=False)
    assert response.is_async and response.status_code == 206
    assert file.tell() == 1000  # nothing read yet
    assert _collected(response) == data[1000:]


def test_a_file_built_for_each_request_is_sent_whole_and_says_it_takes_no_ranges():
    """The logs archive: a range of one request's archive would be spliced onto another's."""
    request = RequestFactory().get("/logs", headers={"Range": "bytes=0-9"})
    response = file_response(
        request, io.BytesIO(b"x" * 100), filename="logs.tar.gz", attachment=True, ranges=False
    )
    assert (response.status_code, response["Accept-Ranges"]) == (200, "none")
    assert response["Content-Length"] == "100"
    assert b"".join(response.streaming_content) == b"x" * 100
    assert response["Content-Type"] == "application/gzip"  # guessed from the name, as before
