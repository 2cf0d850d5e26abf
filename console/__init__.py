"""The Pitlane Django project and the shell of the site."""

from console.celery import app as celery_app

__all__ = ("celery_app",)
