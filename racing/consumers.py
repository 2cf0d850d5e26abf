"""The live leaderboard: ``ws/events/<id>/`` relays the event's ``event_<id>`` group.

Anyone who may see the event may listen (public events need no login). Messages are JSON:
``leaderboard`` when the rankings changed, ``submission`` when a submission's status or score
did, ``queue``, ``timing`` and ``winner`` for live and physical races (see ``racing.broadcasts``).

``ws/live-turns/<evaluation id>/`` streams a live race's turn (its evaluation's frames, as
``training.consumers`` streams an evaluation to its owner) to everyone who may see the event.
"""

from __future__ import annotations

import json

from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer

from common.sockets import ClosesOnLayerOutage
from racing import selectors
from racing.broadcasts import event_group
from racing.models import Event, LiveEntry
from training import selectors as training_selectors
from training.consumers import LiveConsumer
from training.streams import evaluation_group

REFUSED = 4404


class EventConsumer(ClosesOnLayerOutage, AsyncWebsocketConsumer):
    async def connect(self) -> None:
        pk = self.scope["url_route"]["kwargs"]["pk"]
        if not await database_sync_to_async(self.may_watch)(self.scope.get("user"), pk):
            await self.close(code=REFUSED)
            return
        self.group = event_group(pk)
        await self.channel_layer.group_add(self.group, self.channel_name)
        await self.accept()

    async def disconnect(self, code: int) -> None:
        if hasattr(self, "group"):
            await self.channel_layer.group_discard(self.group, self.channel_name)

    async def event_update(self, event: dict) -> None:
        await self.send(text_data=json.dumps(event["message"]))

    @staticmethod
    def may_watch(user, pk: int) -> bool:
        event = Event.objects.filter(pk=pk).first()
        if event is None:
            return False
        if user is None:
            return event.public
        return selectors.event_visible_to(event=event, user=user)


class LiveTurnConsumer(LiveConsumer):
    """A live race's turn on the race and broadcast pages: its frames, status and laps."""

    anonymous = True

    def group_for(self, pk: int) -> str:
        return evaluation_group(pk)

    def snapshot_for(self, user, pk: int) -> dict | None:
        entry = (
            LiveEntry.objects.select_related("submission__evaluation", "session__event")
            .filter(submission__evaluation_id=pk)
            .first()
        )
        if entry is None or not EventConsumer.may_watch(
            user if user.is_authenticated else None, entry.session.event_id
        ):
            return None
        return training_selectors.evaluation_snapshot(evaluation=entry.submission.evaluation)
