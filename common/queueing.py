"""Queueing a task by its name: a service sends ``training.train`` without importing the module
that defines it, so an app never imports the apps above it to queue their work (the layers in
pyproject.toml). The task's queue comes from the name too (``CELERY_TASK_ROUTES``), as for a
task object's ``delay``; a test checks that every name sent is a task the workers know."""

from __future__ import annotations

from celery import current_app


def enqueue(name: str, *args: object) -> None:
    """Send the task called ``name`` with positional ``args`` to the queue its route names."""
    current_app.send_task(name, args=args)
