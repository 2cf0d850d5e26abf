"""The archive kept for a racer's import (``archives.kept_uploads``) cannot fill the disk: one per
racer, tied to the racer, its size on the import page; deleted when a new one replaces it, on
Cancel, at logout, once imported and by the workers' housekeeping when it expires; and the
console's kept uploads together have a ceiling, past which a new one is refused in words."""

from __future__ import annotations

from datetime import timedelta

import pytest
from django.core.files.uploadedfile import SimpleUploadedFile
from django.urls import reverse

from archives import kept_uploads
from archives.members import ImportRefused
from archives.models import KEPT_FOR, KeptUpload
from console import recovery
from tests.helpers.archives import CHECKED_IMPORT, deepracer_folder
from training import artifacts
from training.models import RLModel

pytestmark = pytest.mark.django_db

BAD_NAME = "not a name!"  # the form is to correct before the archive is read: it is kept


def post_to_correct(client, content: bytes, filename: str = "model.tar.gz", name: str = BAD_NAME):
    upload = SimpleUploadedFile(filename, content)
    return client.post(reverse("archives:model-import"), {"name": name, "archive": upload})


def stored(kept: KeptUpload) -> bool:
    return artifacts.default_storage.exists(kept.name)


def test_a_second_upload_replaces_the_first_and_its_bytes(alice, client):
    client.force_login(alice)
    post_to_correct(client, b"first" * 1000, "first.tar.gz")
    first = KeptUpload.objects.get(racer=alice)
    assert stored(first) and first.size == 5000

    response = post_to_correct(client, b"second" * 2000, "second.tar.gz")
    second = KeptUpload.objects.get(racer=alice)  # one, the racer's: not one per session
    assert not stored(first) and stored(second) and second.size == 12000
    assert "Using <strong>second.tar.gz</strong> you uploaded" in response.text
    assert "<strong>second.tar.gz</strong> (11.7\xa0KB) is kept for you until" in response.text

    # In another browser the racer sees it too, and may use it or cancel it.
    other = type(client)()
    other.force_login(alice)
    page = other.get(reverse("archives:model-import")).text
    assert f'name="kept" value="{second.token}"' in page and ">Cancel</button>" in page


def test_a_racer_keeps_one_archive_of_at_most_the_imports_maximum(alice, monkeypatch):
    monkeypatch.setattr(kept_uploads, "MAX_ARCHIVE", 1000)
    with pytest.raises(kept_uploads.UploadNotKept, match="The archive is over 1,000 bytes"):
        kept_uploads.upload_keep(racer=alice, upload=SimpleUploadedFile("big.tar.gz", bytes(1001)))
    assert not KeptUpload.objects.exists()


def test_logging_out_deletes_the_racers_kept_upload(alice, client):
    client.force_login(alice)
    post_to_correct(client, b"archive" * 100)
    kept = KeptUpload.objects.get(racer=alice)
    client.post(reverse("logout"))
    assert not KeptUpload.objects.exists() and not stored(kept)


def test_cancel_deletes_the_kept_upload_and_says_so(alice, bob, client):
    client.force_login(bob)
    post_to_correct(client, b"bobs" * 100)
    client.force_login(alice)
    post_to_correct(client, b"alices" * 100, "mine.tar.gz")
    kept = KeptUpload.objects.get(racer=alice)
    response = client.post(reverse("archives:model-import-cancel"), follow=True)
    assert "Cancelled: mine.tar.gz is deleted, nothing was imported." in response.text
    assert not stored(kept) and not KeptUpload.objects.filter(racer=alice).exists()
    assert KeptUpload.objects.filter(racer=bob).exists()  # another racer's stays
    assert client.get(reverse("archives:model-import-cancel")).status_code == 405


def test_the_workers_housekeeping_deletes_an_expired_upload(alice, bob):
    old = kept_uploads.upload_keep(racer=alice, upload=SimpleUploadedFile("a.tar.gz", b"a" * 10))
    new = kept_uploads.upload_keep(racer=bob, upload=SimpleUploadedFile("b.tar.gz", b"b" * 10))
    KeptUpload.objects.filter(pk=old.pk).update(kept_at=old.kept_at - KEPT_FOR)
    assert kept_uploads.upload_kept(racer=alice, token=old.token) is None  # expired: not used

    removed = recovery.resume_lapsed()  # what every worker's heartbeat runs
    assert f"upload kept for racer {alice.pk}'s import expired; it was deleted" in removed
    assert not stored(old) and stored(new)
    with pytest.raises(ImportRefused, match="no longer kept"):  # a confirm that found it before
        kept_uploads.upload_open(old)
    assert list(KeptUpload.objects.all()) == [new]


def test_a_full_console_refuses_a_new_upload_in_words_and_keeps_the_form(
    alice, bob, client, settings
):
    settings.PITLANE_KEPT_UPLOADS_MAX = 10_000
    bobs = kept_uploads.upload_keep(racer=bob, upload=SimpleUploadedFile("b.tar.gz", bytes(6000)))
    KeptUpload.objects.filter(pk=bobs.pk).update(kept_at=bobs.kept_at - timedelta(minutes=50))
    client.force_login(alice)
    response = post_to_correct(client, bytes(5000), "mine.tar.gz", name="my-model!")
    assert response.status_code == 400
    page = response.text.replace("&#x27;", "'")
    assert (
        "The console is holding too many imports waiting for their racers (6,000 bytes of "
        "10,000 bytes), so this archive cannot be kept for you to confirm. Try again in a few "
        "minutes: each is deleted once used, cancelled or 1 hour old, the next within 10 min."
    ) in page
    assert 'value="my-model!"' in page  # what the racer typed stays
    assert "you uploaded" not in page and list(KeptUpload.objects.all()) == [bobs]

    # Once Bob's is gone, Alice's fits; and a racer's own previous upload never counts.
    client.force_login(bob)
    client.post(reverse("archives:model-import-cancel"))
    client.force_login(alice)
    post_to_correct(client, bytes(5000))
    post_to_correct(client, bytes(9000))
    assert KeptUpload.objects.get().size == 9000


@pytest.mark.slow
@CHECKED_IMPORT
def test_a_preview_the_console_cannot_keep_is_refused_in_words_with_retry_after(
    alice, bob, tracks, client, settings
):
    settings.PITLANE_KEPT_UPLOADS_MAX = 2 * len(deepracer_folder()) - 1
    kept_uploads.upload_keep(racer=bob, upload=SimpleUploadedFile("b.tar.gz", deepracer_folder()))
    client.force_login(alice)
    upload = SimpleUploadedFile("mine.tar.gz", deepracer_folder())
    response = client.post(reverse("archives:model-import"), {"name": "mine", "archive": upload})
    assert response.status_code == 503 and int(response["Retry-After"]) > 3000
    assert "The console is holding too many imports waiting for their racers" in response.text
    assert "What the import creates" not in response.text and 'value="mine"' in response.text
    assert KeptUpload.objects.get().racer == bob and not RLModel.objects.exists()


@pytest.mark.parametrize("refused", ["over the racer's allowance", "over the console's total"])
def test_a_refused_second_upload_leaves_the_first_kept(alice, bob, monkeypatch, settings, refused):
    monkeypatch.setattr(kept_uploads, "MAX_ARCHIVE", 5000)
    settings.PITLANE_KEPT_UPLOADS_MAX = 10_000
    kept_uploads.upload_keep(racer=bob, upload=SimpleUploadedFile("b.tar.gz", bytes(4000)))
    first = kept_uploads.upload_keep(
        racer=alice, upload=SimpleUploadedFile("a.tar.gz", bytes(3000))
    )
    second = bytes(5001) if refused == "over the racer's allowance" else bytes(5000)
    if refused == "over the console's total":
        settings.PITLANE_KEPT_UPLOADS_MAX = 8000  # 4,000 + 5,000 without Alice's first: over
    with pytest.raises(kept_uploads.UploadNotKept):
        kept_uploads.upload_keep(racer=alice, upload=SimpleUploadedFile("a2.tar.gz", second))
    assert KeptUpload.objects.get(racer=alice) == first and stored(first)
    assert first.size == 3000


def test_a_racers_own_kept_upload_does_not_count_against_the_console_total(alice, settings):
    settings.PITLANE_KEPT_UPLOADS_MAX = 10_000
    kept_uploads.upload_keep(racer=alice, upload=SimpleUploadedFile("a.tar.gz", bytes(6000)))
    second = kept_uploads.upload_keep(
        racer=alice, upload=SimpleUploadedFile("b.tar.gz", bytes(9000))
    )
    assert list(KeptUpload.objects.all()) == [second] and stored(second)
