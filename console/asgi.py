"""The ASGI application Daphne serves: views over HTTP, consumers over websockets."""

import os

from django.core.asgi import get_asgi_application

os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
# Django must be set up before the consumers (and the models they import) are.
django_asgi_app = get_asgi_application()

from channels.auth import AuthMiddlewareStack  # noqa: E402
from channels.routing import ProtocolTypeRouter, URLRouter  # noqa: E402
from channels.security.websocket import AllowedHostsOriginValidator  # noqa: E402

from console import daphne_body  # noqa: E402
from console.bodylimit import BodyLimit  # noqa: E402
from console.routing import websocket_urlpatterns  # noqa: E402

# Daphne loads this module before it listens: its requests keep a body only to its limit, on disk.
daphne_body.install()
application = ProtocolTypeRouter(
    {
        "http": daphne_body.BodyFromFile(BodyLimit(django_asgi_app)),
        "websocket": AllowedHostsOriginValidator(
            AuthMiddlewareStack(URLRouter(websocket_urlpatterns))
        ),
    }
)
