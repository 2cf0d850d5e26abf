"""var/ is its owner's alone: another user of the machine reads nothing there, neither what an
earlier install left readable nor what the console creates; uploads a killed web server left in
it are swept by the workers' housekeeping."""

from __future__ import annotations

import os
import stat
import time
from pathlib import Path

import pytest
from celery import signals
from django.conf import settings
from django.core.files.base import ContentFile
from django.core.files.storage import default_storage
from django.core.files.uploadedfile import TemporaryUploadedFile

from console import workers
from console.private_files import data_dir_private, temporary_uploads_sweep
from tests.helpers.private_files import (
    an_install_from_before,
    as_nobody,
    read_as_another_user,
)


def mode(path: Path) -> int:
    return stat.S_IMODE(path.lstat().st_mode)


def test_it_lets_no_other_user_read_what_an_earlier_install_left(tmp_path):
    var = tmp_path / "var"
    an_install_from_before(var)
    (var / "run.sh").write_text("#!/bin/sh\n")
    (var / "run.sh").chmod(0o755)
    outside = tmp_path / "elsewhere.txt"
    outside.write_text("not var/'s")
    outside.chmod(0o644)
    (var / "media" / "link").symlink_to(outside)
    assert read_as_another_user(var, ["db.sqlite3"]) == {"db.sqlite3": "read"}  # as it was

    data_dir_private(var)

    names = [".", "db.sqlite3", "db.sqlite3-wal", "redis/dump.rdb", "media/models/1/best.pt"]
    assert read_as_another_user(var, names) == dict.fromkeys(names, "EACCES")
    assert {mode(path) for path in var.rglob("*") if not path.is_symlink()} == {0o700, 0o600}
    assert mode(var / "run.sh") == 0o700  # its owner keeps what they had
    assert mode(outside) == 0o644  # a link is not followed


def test_it_stores_an_upload_and_its_folders_for_their_owner_only(db):
    name = default_storage.save(f"private-{time.monotonic_ns()}/upload.tar.gz", ContentFile(b"x"))
    stored = Path(default_storage.path(name))
    try:
        assert (mode(stored), mode(stored.parent)) == (0o600, 0o700)
        assert read_as_another_user(stored.parent, ["upload.tar.gz"]) == {"upload.tar.gz": "EACCES"}
    finally:
        default_storage.delete(name)
        stored.parent.rmdir()


def test_it_spools_an_upload_in_progress_under_var_for_its_owner_only():
    spool = Path(settings.FILE_UPLOAD_TEMP_DIR)
    assert spool.parent == settings.VAR_DIR and mode(spool) == 0o700
    upload = TemporaryUploadedFile("model.tar.gz", "application/gzip", 0, None)
    try:
        assert Path(upload.temporary_file_path()).parent == spool
        assert mode(Path(upload.temporary_file_path())) == 0o600
    finally:
        upload.close()


def test_it_sweeps_the_uploads_a_killed_web_server_left_and_keeps_those_in_progress(
    tmp_path, settings, caplog
):
    settings.FILE_UPLOAD_TEMP_DIR = str(tmp_path)
    left = tmp_path / "tmpa1b2.upload.gz"
    left.write_bytes(b"x" * 1000)
    an_hour_ago = time.time() - 3601
    os.utime(left, (an_hour_ago, an_hour_ago))
    arriving = tmp_path / "tmpc3d4.upload.gz"
    arriving.write_bytes(b"y")
    outside = tmp_path.parent / f"{tmp_path.name}-kept.txt"
    outside.write_text("not an upload")
    os.utime(outside, (an_hour_ago, an_hour_ago))
    (tmp_path / "link").symlink_to(outside)

    workers._sweep_temporary_uploads()  # what every worker's heartbeat does

    assert sorted(path.name for path in tmp_path.iterdir()) == ["link", "tmpc3d4.upload.gz"]
    assert outside.exists()
    assert "temporary upload tmpa1b2.upload.gz (1,000 bytes) was left by a stopped web" in (
        caplog.text
    )
    assert temporary_uploads_sweep(tmp_path / "gone") == []


@pytest.mark.parametrize("started", [signals.celeryd_init, signals.beat_init])
def test_a_worker_or_scheduler_started_on_its_own_creates_files_for_its_owner_only(started):
    before = os.umask(0o022)
    try:
        started.send(sender=None)
        assert os.umask(0o022) == 0o077
    finally:
        os.umask(before)


def test_a_start_among_files_that_are_not_its_users_says_so_and_goes_on(tmp_path, caplog):
    """A var/ left by a ``sudo make run`` holds root's files: the console started by its user
    cannot change them, says which, and starts all the same (a traceback stopped it)."""
    var = tmp_path / "var"
    an_install_from_before(var)

    def start(above: int) -> bytes:  # as nobody, among root's files
        os.fchdir(above)
        with caplog.at_level("WARNING", logger="console.private_files"):
            changed = data_dir_private(Path("."))
        return f"{changed} {len(caplog.records)}".encode()

    said = as_nobody(var, start).decode()
    changed, warned = map(int, said.split())
    assert changed == 0 and warned >= 1  # nothing changed, and the log says which file
    assert mode(var / "db.sqlite3") == 0o644
