"""Every websocket route of the site; each app adds its consumers here."""

from django.urls import path

from console import consumers
from racing import consumers as racing_consumers
from training import consumers as training_consumers

websocket_urlpatterns = [
    path("ws/system/probe/", consumers.WorkerProbeConsumer.as_asgi()),
    path("ws/jobs/<int:pk>/", training_consumers.TrainingConsumer.as_asgi()),
    path("ws/evaluations/<int:pk>/", training_consumers.EvaluationConsumer.as_asgi()),
    path("ws/events/<int:pk>/", racing_consumers.EventConsumer.as_asgi()),
    path("ws/live-turns/<int:pk>/", racing_consumers.LiveTurnConsumer.as_asgi()),
]
