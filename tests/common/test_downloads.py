"""Which bytes a Range header asks for (RFC 9110 section 14): one range is answered, a range past
the end is refused, and anything else gets the whole file."""

import pytest

from common.downloads import Unsatisfiable, byte_range


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
    "header", ["", "bytes=", "bytes=-", "bytes=9-3", "items=0-9", "bytes=0-9,20-29", "bytes=a-b"]
)
def test_it_answers_the_whole_file_for_no_range_an_unreadable_one_or_several(header):
    assert byte_range(header, 100) is None


@pytest.mark.parametrize(
    ("header", "size"), [("bytes=100-", 100), ("bytes=-0", 100), ("bytes=-5", 0)]
)
def test_it_refuses_a_range_that_no_byte_of_the_file_is_in(header, size):
    with pytest.raises(Unsatisfiable):
        byte_range(header, size)
