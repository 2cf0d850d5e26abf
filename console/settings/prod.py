"""Several machines behind HTTPS. Required: DJANGO_SECRET_KEY, DJANGO_ALLOWED_HOSTS, DATABASE_URL,
REDIS_URL. Optional: PITLANE_S3_BUCKET (with its region, endpoint and credentials),
DJANGO_CSRF_TRUSTED_ORIGINS, PITLANE_HSTS_SECONDS. Run ``manage.py collectstatic`` when deploying.
"""

from django.core.exceptions import ImproperlyConfigured

from console.settings.base import *  # noqa: F403
from console.settings.base import env

DEBUG = False
SECRET_KEY = env.secret_key("DJANGO_SECRET_KEY")
ALLOWED_HOSTS = env.list("DJANGO_ALLOWED_HOSTS")
if "*" in ALLOWED_HOSTS:  # any Host header: password-reset links and CSRF checks trust it
    raise ImproperlyConfigured(
        "The environment variable DJANGO_ALLOWED_HOSTS must name the console's hosts; "
        "'*' accepts any Host header, which production refuses."
    )
# In production the database and Redis are named explicitly, never the one-machine defaults.
env.str("DATABASE_URL")
env.str("REDIS_URL")

# HTTPS is terminated by the proxy in front of Daphne, which says so in X-Forwarded-Proto.
SECURE_PROXY_SSL_HEADER = ("HTTP_X_FORWARDED_PROTO", "https")
SECURE_SSL_REDIRECT = env.bool("PITLANE_SSL_REDIRECT", True)
SECURE_REDIRECT_EXEMPT = [r"^healthz$"]
SECURE_HSTS_SECONDS = env.int("PITLANE_HSTS_SECONDS", 31_536_000, minimum=0)
SECURE_HSTS_INCLUDE_SUBDOMAINS = True
SECURE_HSTS_PRELOAD = True
SECURE_CONTENT_TYPE_NOSNIFF = True
SESSION_COOKIE_SECURE = True
CSRF_COOKIE_SECURE = True
X_FRAME_OPTIONS = "DENY"
