"""A WSGI entry point for HTTP-only deployments; websockets need console.asgi."""

import os

from django.core.wsgi import get_wsgi_application

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
application = get_wsgi_application()
