"""Viewers of the live streams over the real ASGI application, and the frames they receive."""

import json
import struct

from asgiref.sync import sync_to_async
from channels.testing import WebsocketCommunicator
from django.conf import settings
from django.test import Client

ORIGIN = (b"origin", b"http://127.0.0.1:8000")


def login_cookie(user) -> bytes:
    """A session cookie of ``user``'s, logged in."""
    client = Client()
    client.force_login(user)
    return f"{settings.SESSION_COOKIE_NAME}={client.cookies[settings.SESSION_COOKIE_NAME].value}"


async def viewer(path: str, user=None, origin=ORIGIN) -> WebsocketCommunicator:
    """A websocket client of ``path``, not yet connected: from ``origin``, logged in as ``user``
    when given."""
    from console.asgi import application

    headers = [origin]
    if user is not None:
        headers.append((b"cookie", (await sync_to_async(login_cookie)(user)).encode()))
    return WebsocketCommunicator(application, path, headers=headers)


def frame_header(message: bytes) -> tuple[dict, bytes]:
    """A frame's message split: its header, and the image after it."""
    (length,) = struct.unpack("!I", message[:4])
    return json.loads(message[4 : 4 + length]), message[4 + length :]
