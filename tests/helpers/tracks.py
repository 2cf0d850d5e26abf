"""Route files as staff bring them: one whose header claims more than it holds, and the admin's
upload of one."""

import io

import numpy as np
from django.core.files.uploadedfile import SimpleUploadedFile
from django.urls import reverse

from tests import routes


def claiming(shape: tuple[int, ...]) -> bytes:
    """A route file of 60 waypoints whose header claims ``shape``: read as it claims, it would
    take ``prod(shape) * 8`` bytes."""
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buffer, {"descr": "<f8", "fortran_order": False, "shape": shape}
    )
    return buffer.getvalue() + routes.counterclockwise()[:60].tobytes()


def upload(client, kind: str, name: str):
    """``client`` posts the admin's add-track form: ``kind``'s route file (tests.routes), as
    ``name``."""
    data = {
        "route_file": SimpleUploadedFile(f"{kind}.npy", routes.route_bytes(kind)),
        "name": name,
        "display_name": "Upload",
        "description": "From the admin",
        "difficulty": "beginner",
        "directions": ["counterclockwise", "clockwise"],
    }
    return client.post(reverse("admin:training_track_add"), data)
