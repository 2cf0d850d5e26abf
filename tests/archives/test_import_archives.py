"""An archive as racers pack it imports; a malformed one is refused in words, never with a
server error; and only imports that arrive count against the racer's hourly import limit."""

from __future__ import annotations

import contextlib
import html
import io
import re
import subprocess
import tarfile
import tracemalloc

import pytest
from django.contrib.sessions.backends.db import SessionStore
from django.core.files.uploadedfile import SimpleUploadedFile
from django.test import RequestFactory
from django.urls import reverse
from django_ratelimit import core as ratelimit_core
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from archives import history, imports, views
from common import documents
from tests.helpers.archives import CHECKED_IMPORT, deepracer_export, tar_gz, virtual_archive
from tests.helpers.models import ready_model
from training import artifacts
from training.models import RLModel

pytestmark = pytest.mark.django_db


def packed_from_a_folder(archive: bytes, folder) -> bytes:
    """``archive`` unpacked into ``folder`` and packed again as racers do:
    ``tar czf m.tar.gz -C folder .``, which starts with the folder itself, ``./``."""
    with tarfile.open(fileobj=io.BytesIO(archive), mode="r:gz") as tar:
        tar.extractall(folder, filter="data")
    packed = folder.parent / "m.tar.gz"
    subprocess.run(["tar", "czf", str(packed), "-C", str(folder), "."], check=True)
    return packed.read_bytes()


@pytest.mark.slow
def test_a_model_folder_packed_with_tar_c_folder_dot_imports(alice, bob, tracks, tmp_path):
    data = packed_from_a_folder(virtual_archive(ready_model(alice)), tmp_path / "folder")
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        assert tar.getnames()[0] == "."  # the bare ./ entry that answered 500
    imported = imports.import_model(owner=bob, archive=io.BytesIO(data))
    assert imported.model.status == RLModel.Status.READY
    assert imported.model.name == "straight-ahead"


@pytest.mark.slow
@CHECKED_IMPORT
def test_the_import_page_takes_a_folder_packed_with_tar_c_folder_dot(
    alice, tracks, client, tmp_path
):
    data = packed_from_a_folder(virtual_archive(ready_model(alice)), tmp_path / "folder")
    client.force_login(alice)
    upload = SimpleUploadedFile("m.tar.gz", data)
    response = client.post(reverse("archives:model-import"), {"archive": upload, "name": "packed"})
    model = RLModel.objects.get(owner=alice, name="packed")
    assert response.status_code == 302 and response["Location"].endswith(f"/models/{model.pk}/")


def named(name: str, kind: bytes = tarfile.REGTYPE, **attributes):
    """A tweak for ``tar_gz``: one more member called ``name``, of type ``kind``."""

    def tweak(tar: tarfile.TarFile) -> None:
        info = tarfile.TarInfo(name)
        info.type = kind
        for key, value in attributes.items():
            setattr(info, key, value)
        info.size = 1 if kind == tarfile.REGTYPE else 0
        tar.addfile(info, io.BytesIO(b"x") if kind == tarfile.REGTYPE else None)

    return tweak


def pax_named(name: str):
    """A member whose name comes in a pax header, where a NUL or any character may stand."""

    def tweak(tar: tarfile.TarFile) -> None:
        info = tarfile.TarInfo("placeholder")
        info.pax_headers = {"path": name}
        info.size = 1
        tar.addfile(info, io.BytesIO(b"x"))

    return tweak


MALFORMED = {
    "empty": named(""),
    "dot as a file": named("."),
    "dot slash as a file": named("./", tarfile.REGTYPE),
    "parent": named(".."),
    "up and out": named("../x"),
    "in and out": named("a/../../b"),
    "absolute": named("/etc/passwd"),
    "backslashes": named("a\\..\\..\\b"),
    "a drive": named("C:/x"),
    "NUL": pax_named("a\x00b"),
    "over-long": pax_named("a/" * 3000),
    "symbolic link": named("l", tarfile.SYMTYPE, linkname="/etc/passwd"),
    "hard link": named("h", tarfile.LNKTYPE, linkname="model_metadata.json"),
    "device": named("d", tarfile.CHRTYPE, devmajor=1, devminor=3),
    "fifo": named("p", tarfile.FIFOTYPE),
    "folder called ..": named("..", tarfile.DIRTYPE),
    "absolute folder": named("/", tarfile.DIRTYPE),
}


OUTSIDE = "is not a relative path inside the archive."
NO_NAME = "is a file without a name."
NOT_A_FILE = "is a link or a device: models hold files."
# What each is told: the member's name as the archive has it (tarfile reads "/" as ""), and why.
SAID = {
    "empty": f"'' {OUTSIDE}",
    "dot as a file": f"'.' {NO_NAME}",
    "dot slash as a file": f"'./' {NO_NAME}",
    "parent": f"'..' {OUTSIDE}",
    "up and out": f"'../x' {OUTSIDE}",
    "in and out": f"'a/../../b' {OUTSIDE}",
    "absolute": f"'/etc/passwd' {OUTSIDE}",
    "backslashes": f"'a\\\\..\\\\..\\\\b' {OUTSIDE}",
    "a drive": f"'C:/x' {OUTSIDE}",
    "NUL": f"'a\\x00b' {OUTSIDE}",
    "over-long": "A file in the archive has a name of 5,999 characters; the limit is 4,096.",
    "symbolic link": f"'l' {NOT_A_FILE}",
    "hard link": f"'h' {NOT_A_FILE}",
    "device": f"'d' {NOT_A_FILE}",
    "fifo": f"'p' {NOT_A_FILE}",
    "folder called ..": f"'..' {OUTSIDE}",
    "absolute folder": f"'' {OUTSIDE}",
}


@pytest.mark.parametrize("case", MALFORMED)
def test_each_malformed_member_name_is_refused_in_words(case):
    archive = io.BytesIO(tar_gz(deepracer_export(), pax_format(MALFORMED[case])))
    with pytest.raises(imports.ImportRefused) as refused:
        imports.read_archive(archive)
    assert str(refused.value).endswith(".") and "Traceback" not in str(refused.value)
    assert str(refused.value) == SAID[case]


def pax_format(tweak):
    def packed(tar: tarfile.TarFile) -> None:
        tar.format = tarfile.PAX_FORMAT
        tweak(tar)

    return packed


PIECES = st.sampled_from(["a", ".", "..", "/", "\\", ":", "\x00", " ", "é", "model_metadata.json"])
KINDS = st.sampled_from([tarfile.REGTYPE, tarfile.DIRTYPE, tarfile.SYMTYPE, tarfile.CHRTYPE])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    names=st.lists(st.lists(PIECES, max_size=8).map("".join), min_size=1, max_size=3), kind=KINDS
)
def test_whatever_the_member_names_reading_an_archive_only_ever_refuses(names, kind):
    def tweak(tar: tarfile.TarFile) -> None:
        tar.format = tarfile.PAX_FORMAT
        for name in names:
            named(name, kind, linkname="x")(tar)

    archive = io.BytesIO(tar_gz(deepracer_export(), tweak))
    try:
        members = imports.read_archive(archive)
    except imports.ImportRefused:
        return
    assert all(
        path and not path.startswith("/") and ".." not in path.split("/") for path in members
    )


@CHECKED_IMPORT
def test_the_import_page_answers_each_malformed_name_with_a_refusal_not_a_500(
    alice, tracks, client, settings
):
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "import-refused": "100/m"}
    client.force_login(alice)
    for case, tweak in MALFORMED.items():
        data = tar_gz(deepracer_export(), pax_format(tweak))
        upload = SimpleUploadedFile("model.tar.gz", data)
        response = client.post(reverse("archives:model-import"), {"archive": upload})
        assert response.status_code == 400, case
        with pytest.raises(imports.ImportRefused) as refused:
            imports.read_archive(io.BytesIO(data))
        assert html.escape(str(refused.value)) in response.text, case
        assert "Traceback" not in response.text
    assert not RLModel.objects.exists()


def post_import(client, data: bytes, name: str = ""):
    upload = SimpleUploadedFile("model.tar.gz", data)
    return client.post(reverse("archives:model-import"), {"archive": upload, "name": name})


NOT_AN_ARCHIVE = b"just some notes, not a model"


@pytest.fixture
def windows_held(monkeypatch) -> None:
    """Each rate's window as it was at its first count: django-ratelimit's hour windows end at an
    offset of each key's own within the hour (``_get_window``), and one that ended between a
    test's imports (once in a suite's run, 2026-12-01) would start its count again."""
    window, windows = ratelimit_core._get_window, {}
    monkeypatch.setattr(
        ratelimit_core,
        "_get_window",
        lambda value, period: windows.setdefault((value, period), window(value, period)),
    )


@pytest.mark.slow
@CHECKED_IMPORT
def test_refused_imports_do_not_use_up_the_hours_imports(
    alice, tracks, client, settings, windows_held
):
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "import": "2/h", "import-refused": "5/h"}
    archive = virtual_archive(ready_model(alice))
    client.force_login(alice)
    for _ in range(2):
        assert post_import(client, NOT_AN_ARCHIVE).status_code == 400
    assert post_import(client, archive, "first").status_code == 302
    assert post_import(client, archive, "second").status_code == 302
    # Imports that arrived count: a third in the hour waits.
    response = post_import(client, archive, "third")
    assert response.status_code == 429
    assert "Too many imports for now: try again in" in response.text
    assert not RLModel.objects.filter(name="third").exists()


def test_imports_posted_in_parallel_count_each_other_before_either_ends(alice, settings):
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "import": "1/h", "import-refused": "5/h"}

    def posted():
        request = RequestFactory().post(reverse("archives:model-import"), {"name": "twin"})
        request.user, request.session = alice, SessionStore()
        return request

    first = views._ModelImportAttempt(posted())  # its import still running
    second = views._ModelImportAttempt(posted())
    assert first.limited is None
    assert str(second.limited).startswith("Too many imports for now: try again in")


def test_refused_imports_have_a_looser_limit_of_their_own_which_says_so(bob, client, settings):
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "import": "1/h", "import-refused": "3/h"}
    client.force_login(bob)
    for _ in range(3):
        response = post_import(client, NOT_AN_ARCHIVE)
        assert response.status_code == 400 and "not a .tar.gz model archive" in response.text
    response = post_import(client, NOT_AN_ARCHIVE)
    assert response.status_code == 429
    assert "Too many refused or unconfirmed imports for now: try again in" in response.text


def sparse(name: str, size: int):
    """A tweak for ``tar_gz``: a GNU sparse member of ``size`` bytes, all of them a hole: a
    512-byte header that tarfile reads as a file of ``size`` zeros."""

    def tweak(tar: tarfile.TarFile) -> None:
        info = tarfile.TarInfo(name)
        info.type, info.size = tarfile.GNUTYPE_SPARSE, 0  # no data stored: one hole
        header = bytearray(info.tobuf(tarfile.GNU_FORMAT))
        header[483:495] = tarfile.itn(size, 12, tarfile.GNU_FORMAT)  # the file's real size
        header[148:156] = b" " * 8
        header[148:155] = b"%06o\0" % sum(header)  # the checksum, counting itself as spaces
        tar.fileobj.write(header)
        tar.offset += len(header)

    return tweak


def test_sparse_tweak_packs_a_huge_member_in_a_few_bytes():
    data = tar_gz({}, sparse("reward_function.py", 500 * imports.MiB))
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        (member,) = tar.getmembers()
        assert member.isfile() and member.size == 500 * imports.MiB
        assert tar.extractfile(member).read(4) == b"\0" * 4
    assert len(data) < 1024


def peak_memory_growth(read) -> int:
    """[bytes] the most Python's allocations grew by while ``read()`` ran."""
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        with contextlib.suppress(imports.ImportRefused):
            read()
        return tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize(
    ("path", "limit"),
    [("reward_function.py", "1 MiB"), ("model_metadata.json", "262,144 bytes"),
     ("training_params.yaml", "262,144 bytes"), ("checkpoints/best.safetensors", "256 MiB")],
)  # fmt: skip
def test_a_huge_member_is_refused_from_its_header_before_a_byte_is_read(path, limit):
    members = {name: data for name, data in deepracer_export().items() if name != path}
    archive = io.BytesIO(tar_gz(members, sparse(path, 500 * imports.MiB)))  # 511 KB in the issue
    with pytest.raises(imports.ImportRefused, match=rf"^{re.escape(path)} is over {limit}\.$"):
        imports.read_archive(archive)
    assert peak_memory_growth(lambda: imports.read_archive(archive)) < 4 * imports.MiB


def test_no_file_is_read_past_its_limit_whatever_its_header_says(monkeypatch):
    archive = io.BytesIO(tar_gz({}, sparse("reward_function.py", 500 * imports.MiB)))
    reads, read = [], tarfile.ExFileObject.read
    monkeypatch.setattr(
        tarfile.ExFileObject, "read", lambda self, size=-1: reads.append(size) or read(self, size)
    )
    over = pytest.raises(imports.ImportRefused, match=r"^reward_function\.py is over 100 bytes")
    with tarfile.open(fileobj=archive) as tar, over:
        imports._read(tar, tar.next(), 100)  # as if its header had passed
    assert reads == [101]


def test_the_files_read_are_bounded_together(monkeypatch):
    monkeypatch.setattr(imports, "MAX_READ", 1000)
    archive = io.BytesIO(tar_gz(deepracer_export(**{"model/model_8.pb": b"\x08" * 1000})))
    with pytest.raises(imports.ImportRefused, match="are over 1,000 bytes together"):
        imports.read_archive(archive)


def test_training_metrics_over_their_limit_are_left_unread_not_refused():
    archive = tar_gz(deepracer_export(), sparse(artifacts.TRAINING_METRICS, 100 * imports.MiB))
    members = imports.read_archive(io.BytesIO(archive))
    assert members[artifacts.TRAINING_METRICS] is None
    assert members.over == {artifacts.TRAINING_METRICS}


def nested(depth: int, opening: str, closing: str, inner: str = "1") -> str:
    return opening * depth + inner + closing * depth


# The files (400,000 and 200,000 levels) are now over imports.SETTINGS_LIMIT; these fit
# in it, and are as far past Python's recursion limit.
@pytest.mark.parametrize(
    ("path", "document"),
    [("model_metadata.json", nested(30_000, '{"a": ', "}")),
     ("model_metadata.json", '{"a": ' + "[" * 100_000),  # never closed
     ("training_params.yaml", nested(100_000, "[", "]")),
     ("training_params.yaml", "- " * 100_000 + "x")],
)  # fmt: skip
def test_a_settings_file_nested_too_deep_is_refused_in_words_before_it_is_parsed(
    bob, tracks, path, document
):
    archive = io.BytesIO(tar_gz(deepracer_export(**{path: document.encode()})))
    with pytest.raises(imports.ImportRefused) as refused:
        imports.import_model(owner=bob, archive=archive)
    assert str(refused.value) == (
        f"{path} cannot be read: it nests lists or objects over {documents.MAX_DEPTH} levels deep."
    )


def test_a_yaml_alias_is_refused_a_document_that_holds_itself_or_a_billion_copies(bob, tracks):
    laughs = "a: &a [x, x]\nb: &b [*a, *a]\nc: [*b, *b]\n"
    archive = io.BytesIO(tar_gz(deepracer_export(**{"training_params.yaml": laughs.encode()})))
    with pytest.raises(imports.ImportRefused, match=r"it uses a YAML alias \(\*name\)\.$"):
        imports.import_model(owner=bob, archive=archive)


def test_training_metrics_or_history_nested_too_deep_are_unreadable_in_words():
    deep = nested(400_000, "[", "]").encode()  # as deep as the metadata
    words = f"it nests lists or objects over {documents.MAX_DEPTH} levels deep"
    with pytest.raises(history.Unreadable, match=f"^{words}$"):
        history.read(b'{"metrics": ' + deep + b"}", episodes_per_iteration=10)
    with pytest.raises(history.Unreadable, match=f"^{words}$"):
        history.exact_read(deep)
