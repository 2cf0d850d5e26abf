"""Websockets through a Redis outage: when the channel layer fails under one consumer, every
websocket of the process closes with 4503 (try again later), and the pages' socket
(static/console/socket.js) reconnects with backoff and catches up.

Every socket, not only the one that saw the error: channels_redis receives for the whole process
with one blocking pop that the consumers take turns at (``RedisChannelLayer.receive``), so only
the consumer at the pop when Redis goes sees the error, and a Redis that comes back without its
data has forgotten every group: a socket left open would hear nothing more. Without this, a
Redis error in a consumer (``group_add`` in ``connect``, the layer's receive, ``group_discard`` on
leaving) ends it in a traceback, and Daphne answers the handshake with HTTP 500 or closes the
socket with 1011 (``daphne.ws_protocol.WebSocketProtocol.handle_exception``). How the layer drops
its dead connections: ``CHANNEL_LAYERS`` in ``console/settings/base.py``.
"""

from __future__ import annotations

import contextlib
import logging
import weakref

import redis

logger = logging.getLogger(__name__)

# RFC 6455's 1013 (Try Again Later), in the range Autobahn lets a server use (1000, 3000-4999),
# as HTTP's 503 reads: the server cannot serve the socket for now.
TRY_AGAIN_LATER = 4503
LAYER_ERRORS = (redis.ConnectionError, redis.TimeoutError)

_open: weakref.WeakSet[ClosesOnLayerOutage] = weakref.WeakSet()


class ClosesOnLayerOutage:
    """Mixed in before a Channels websocket consumer: a channel layer error closes every socket of
    the process with ``TRY_AGAIN_LATER`` (the failing one accepted first when its handshake was
    under way: Daphne can only refuse a handshake with 403, which a page takes for a refusal)."""

    accepted = False
    closed = False  # a close was sent, or the browser has left: nothing more is sent

    async def __call__(self, scope, receive, send) -> None:
        _open.add(self)
        try:
            await super().__call__(scope, receive, send)
        except LAYER_ERRORS as error:
            logger.warning("Websockets closed: Redis failed under %s (%s)", scope["path"], error)
            if not self.closed and not self.accepted:
                await self.accept()
            for consumer in [self, *_open]:
                await consumer.close_for_outage()
            await self._let_go()
        finally:
            _open.discard(self)

    async def _let_go(self) -> None:
        """What ``disconnect`` releases (a viewer's renewals), as Channels calls it only for a
        consumer still running; its group membership is left to expire (Redis failed)."""
        with contextlib.suppress(*LAYER_ERRORS):
            await self.disconnect(TRY_AGAIN_LATER)

    async def close_for_outage(self) -> None:
        if self.accepted and not self.closed:
            await self.close(code=TRY_AGAIN_LATER)

    async def accept(self, *args, **kwargs) -> None:
        await super().accept(*args, **kwargs)
        self.accepted = True

    async def close(self, *args, **kwargs) -> None:
        self.closed = True
        await super().close(*args, **kwargs)

    async def websocket_disconnect(self, message: dict) -> None:
        self.closed = True
        await super().websocket_disconnect(message)
