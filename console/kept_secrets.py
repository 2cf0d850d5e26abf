"""Secrets that one machine generates for itself on first start and keeps under var/.

``make run`` needs no environment variables, yet its Django secret key and its private Redis's
password must be neither in the repository nor the same on two machines: each is made once with
``secrets`` and kept in a file that only its owner can read (0600), created atomically so that
two processes starting together agree on one value.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

from console.private_files import private_dir


def kept_secret(path: Path) -> str:
    """The secret kept in ``path``, generated (URL-safe, 50 random bytes) if there is none."""
    private_dir(path.parent)  # var/: its owner's alone
    try:
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return path.read_text().strip()
    with os.fdopen(descriptor, "w") as file:
        file.write(secrets.token_urlsafe(50))
    return path.read_text().strip()
