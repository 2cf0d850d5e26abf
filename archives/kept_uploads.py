"""The archive a racer uploaded to the import page, kept for their next step: a preview to confirm,
or a form to correct (a browser cannot fill a file input in, so it is not sent again).

A racer has at most one (``models.KeptUpload``, tied to the racer, not the browser's session): a
new upload replaces it. Its bytes count against the racer, who may keep one archive of at most
the import's maximum (``imports.MAX_ARCHIVE``), and against the console, whose kept uploads
together may not pass ``PITLANE_KEPT_UPLOADS_MAX``: past it a new one is refused in words. It is
deleted, with its file, when the import uses it, on Cancel, at logout (``discard_at_logout``),
and by every worker's housekeeping once ``KEPT_FOR`` old (``uploads_expire``).
"""

from __future__ import annotations

import logging
import math
import secrets
from pathlib import PurePosixPath
from typing import IO

from django.conf import settings
from django.contrib.auth.models import AbstractBaseUser
from django.core.files.storage import default_storage
from django.core.files.uploadedfile import UploadedFile
from django.db import IntegrityError
from django.db.models import Min, Sum
from django.utils import timezone

from archives.imports import MAX_ARCHIVE, size
from archives.members import ImportRefused
from archives.models import KEPT_FOR, KeptUpload
from common.transactions import outside_transaction

logger = logging.getLogger(__name__)

KEPT_FOLDER = "imports/kept"  # in storage

# A confirmation whose archive is gone: the page's and the API's words.
KEPT_GONE = (
    f"The archive you uploaded is no longer kept (it is kept for "
    f"{KEPT_FOR.total_seconds() / 3600:g} hour after you upload it, until you import it, "
    "cancel or log out): choose it again."
)


class UploadNotKept(Exception):
    """The upload cannot be kept, in words for the racer; ``retry_after`` [s] when it is the
    console that holds too many, else None."""

    def __init__(self, message: str, retry_after: int | None = None) -> None:
        super().__init__(message)
        self.retry_after = retry_after


def upload_open(kept: KeptUpload) -> IO[bytes]:
    """``kept``'s archive; refused in words when it was deleted since it was found (it expired
    or was cancelled in another tab as the racer confirmed)."""
    try:
        return default_storage.open(kept.name, "rb")
    except FileNotFoundError:
        raise ImportRefused(
            "The archive you uploaded is no longer kept (it expired or was cancelled): choose "
            "it again."
        ) from None


def upload_keep(*, racer: AbstractBaseUser, upload: UploadedFile) -> KeptUpload:
    """Keep ``upload`` for the racer's next attempt, replacing (deleting) the one kept before;
    ``UploadNotKept`` when it is over the racer's allowance or the console's, and then the one
    kept before stays (its bytes, which the new one would replace, do not count against the
    console's). The row is written, and the console's total read again, before the file: two
    racers at once may both be refused, never both kept past the total (the one kept before
    is then gone already: only when another racer's upload took the room in that instant)."""
    outside_transaction("An uploaded archive kept in storage")
    _delete_unclaimed_files()
    if upload.size > MAX_ARCHIVE:
        raise UploadNotKept(
            f"The archive is over {size(MAX_ARCHIVE)}, the most an upload kept for you may hold."
        )
    previous = KeptUpload.objects.filter(racer=racer).first() if racer.is_authenticated else None
    others = _kept_total() - (previous.size if previous is not None else 0)
    if others + upload.size > settings.PITLANE_KEPT_UPLOADS_MAX:
        raise _console_full(others)
    upload_discard(racer=racer)  # accepted: the new one replaces it
    token = secrets.token_urlsafe(16)
    try:
        kept = KeptUpload.objects.create(
            racer=racer,
            token=token,
            filename=PurePosixPath(upload.name or "model.tar.gz").name[:120],
            name=f"{KEPT_FOLDER}/{token}.tar.gz",
            size=upload.size,
        )
    except IntegrityError:  # another upload of theirs, sent at the same instant, is kept
        raise UploadNotKept(
            "Another archive you sent at the same moment is kept instead: send this one again."
        ) from None
    if (total := _kept_total()) > settings.PITLANE_KEPT_UPLOADS_MAX:
        kept.delete()
        raise _console_full(total - kept.size)
    try:
        upload.seek(0)
        stored = default_storage.save(kept.name, upload)
    except BaseException:
        kept.delete()
        raise
    if stored != kept.name:
        KeptUpload.objects.filter(pk=kept.pk).update(name=stored)
        kept.name = stored
    return kept


def upload_kept(*, racer: AbstractBaseUser, token: str) -> KeptUpload | None:
    """The archive kept for ``racer`` under ``token`` (the form's hidden field), if it still is."""
    kept = upload_held(racer=racer)
    if kept is None or not token or not secrets.compare_digest(kept.token, token):
        return None
    if not default_storage.exists(kept.name):
        return None
    return kept


def upload_held(*, racer: AbstractBaseUser) -> KeptUpload | None:
    """The archive kept for ``racer``, whatever the form names, unless it has expired."""
    if not racer.is_authenticated:
        return None
    since = timezone.now() - KEPT_FOR
    return KeptUpload.objects.filter(racer=racer, kept_at__gte=since).first()


def upload_discard(*, racer: AbstractBaseUser) -> KeptUpload | None:
    """Forget, and delete, the archive kept for ``racer``; the one deleted, if any."""
    kept = KeptUpload.objects.filter(racer=racer).first() if racer.is_authenticated else None
    if kept is not None:
        _delete(kept)
    return kept


def uploads_expire() -> list[str]:
    """Delete each kept upload ``KEPT_FOR`` old; what was deleted, in words for the log. Every
    worker's housekeeping calls it (``console.recovery.resume_lapsed``)."""
    since = timezone.now() - KEPT_FOR
    deleted = []
    for kept in KeptUpload.objects.filter(kept_at__lt=since):
        _delete(kept)
        deleted.append(f"upload kept for racer {kept.racer_id}'s import expired; it was deleted")
    return deleted


def discard_at_logout(sender, request, user, **kwargs) -> None:
    """``user_logged_out``'s receiver: the racer's kept upload goes with their session."""
    if user is not None:
        upload_discard(racer=user)


def _delete(kept: KeptUpload) -> None:
    """The row first: once it is gone no attempt can open the file."""
    if KeptUpload.objects.filter(pk=kept.pk).delete()[0]:
        try:
            default_storage.delete(kept.name)
        except OSError:
            logger.warning("Could not delete %s; the next upload's sweep will", kept.name)


def _kept_total() -> int:
    return KeptUpload.objects.aggregate(total=Sum("size"))["total"] or 0


def _console_full(held: int) -> UploadNotKept:
    """The words when the console's kept uploads are at their total, and when one will expire."""
    oldest = KeptUpload.objects.aggregate(oldest=Min("kept_at"))["oldest"] or timezone.now()
    wait = max(60, math.ceil((oldest + KEPT_FOR - timezone.now()).total_seconds()))
    return UploadNotKept(
        f"The console is holding too many imports waiting for their racers "
        f"({size(held)} of {size(settings.PITLANE_KEPT_UPLOADS_MAX)}), so this archive cannot be "
        f"kept for you to confirm. Try again in a few minutes: each is deleted once used, "
        f"cancelled or {KEPT_FOR.total_seconds() / 3600:g} hour old, the next within "
        f"{math.ceil(wait / 60)} min.",
        retry_after=wait,
    )


def _delete_unclaimed_files() -> None:
    """Files in ``KEPT_FOLDER`` that no row names and ``KEPT_FOR`` old: their racer's account
    was deleted, or a process died between the row and the file, or they were kept in a
    browser's session before uploads were kept per racer."""
    try:
        _, names = default_storage.listdir(KEPT_FOLDER)
    except FileNotFoundError:
        return
    oldest = timezone.now() - KEPT_FOR
    claimed = set(KeptUpload.objects.values_list("name", flat=True))
    for file in names:
        name = f"{KEPT_FOLDER}/{file}"
        try:
            if name not in claimed and default_storage.get_modified_time(name) < oldest:
                default_storage.delete(name)
        except (FileNotFoundError, NotImplementedError):
            continue
