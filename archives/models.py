"""The archives app's one row: the archive a racer uploaded to the import page that waits for
them (``archives.kept_uploads``)."""

from __future__ import annotations

from datetime import datetime, timedelta

from django.conf import settings
from django.db import models
from django.utils import timezone

KEPT_FOR = timedelta(hours=1)  # then the workers' housekeeping deletes it


class KeptUpload(models.Model):
    """An archive a racer uploaded that waits for their next step: a preview to confirm, or a
    form to correct (a browser cannot fill a file input in, so it is not sent again). One per
    racer (a new upload replaces it); its bytes count against the racer's allowance and the
    console's (``kept_uploads.upload_keep``); deleted, with its file, once the import uses it,
    on Cancel, at logout, and by the workers' housekeeping once ``KEPT_FOR`` old."""

    racer = models.OneToOneField(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="kept_upload"
    )
    token = models.CharField(max_length=32)  # the form's hidden ``kept`` field names it
    filename = models.CharField(max_length=120)  # as the racer chose it
    name = models.CharField(max_length=255)  # in storage
    size = models.PositiveBigIntegerField()  # [bytes]
    kept_at = models.DateTimeField(default=timezone.now, db_index=True)

    def __str__(self) -> str:
        return f"{self.filename} kept for {self.racer}"

    @property
    def expires_at(self) -> datetime:
        return self.kept_at + KEPT_FOR
