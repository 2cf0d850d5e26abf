"""Every websocket route of the site; each app adds its consumers here."""

from django.urls import path

from console import consumers

websocket_urlpatterns = [
    path("ws/system/probe/", consumers.WorkerProbeConsumer.as_asgi()),
]
