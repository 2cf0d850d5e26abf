"""The Celery application. A worker: ``celery -A console worker -Q training,simulation``."""

import os

from celery import Celery

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")

app = Celery("pitlane")
app.config_from_object("django.conf:settings", namespace="CELERY")
app.autodiscover_tasks()

# The worker heartbeat that /healthz reads; imported here so every worker registers it.
import console.workers  # noqa: E402, F401
