"""Staff's import from DeepRacer for Cloud's bucket: a model's prefix (``s3://bucket/prefix``)
read with the console's keys for it (``PITLANE_DRFC_S3``), packed by ``pitlane_client.drfc`` (the
layout, with DeepRacer's sources cited, is the client's: `pitlane import s3://...` reads a
racer's own bucket the same way), and imported as an uploaded archive is, with its best and
last checkpoints (``archives.imports``, every check of an upload's).
"""

from __future__ import annotations

import tempfile

import boto3
from botocore.config import Config
from botocore.exceptions import BotoCoreError, ClientError
from django.conf import settings
from django.contrib.auth.models import AbstractBaseUser
from pitlane_client import drfc

from archives import imports
from archives.members import ImportRefused

# [s] to connect to the bucket's API and for each answer: a bucket that does not answer is said
# so in a minute, not waited on for ever; two tries for a dropped connection.
TIMEOUTS = Config(connect_timeout=10, read_timeout=60, retries={"max_attempts": 2})


def import_from_bucket(*, owner: AbstractBaseUser, url: str, name: str = "") -> imports.Imported:
    """The DeepRacer for Cloud model at ``url`` as ``owner``'s (``imports.import_model``): READY
    with its checkpoints, or with its training queued where it has none. ``ImportRefused`` in
    words for a prefix that holds no model, a bucket that cannot be read, or what the import
    refuses."""
    s3 = boto3.client("s3", config=TIMEOUTS, **settings.PITLANE_DRFC_S3)
    with tempfile.TemporaryFile(dir=settings.FILE_UPLOAD_TEMP_DIR) as archive:
        try:
            packed = drfc.pack(s3, url, archive)
        except drfc.DrfcUnreadable as unreadable:
            raise ImportRefused(str(unreadable)) from None
        except ClientError as error:
            said = error.response.get("Error", {})
            raise ImportRefused(
                f"{url} cannot be read: S3 answered {said.get('Code', 'an error')} "
                f"({said.get('Message', '')}). Check the bucket's name and the console's keys "
                "for it (PITLANE_DRFC_S3_*)."
            ) from None
        except BotoCoreError as error:
            raise ImportRefused(f"{url} cannot be read: {error}.") from None
        imported = imports.import_model(owner=owner, archive=archive, name=name)
    imported.notes = [*packed.notes, *imported.notes]
    return imported
