"""One machine: what ``make run`` serves. Needs no environment variables at all.

The secret key is generated on first start and kept in ``var/secret_key`` (never in the repository).
Debug pages stay off unless DJANGO_DEBUG=true, so racers see readable error pages, not tracebacks.
"""

from console.kept_secrets import kept_secret
from console.settings.base import *  # noqa: F403
from console.settings.base import VAR_DIR, env

SECRET_KEY = env.secret_key("DJANGO_SECRET_KEY", "") or kept_secret(VAR_DIR / "secret_key")

# Static files straight from the source tree, no collectstatic step; changes show on reload.
STORAGES["staticfiles"] = {  # noqa: F405
    "BACKEND": "django.contrib.staticfiles.storage.StaticFilesStorage"
}
WHITENOISE_USE_FINDERS = True
STATIC_ROOT = None  # nothing is collected; WhiteNoise serves from the finders
WHITENOISE_AUTOREFRESH = True
