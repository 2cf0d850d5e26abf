"""The test suite. REDIS_URL points at the throwaway Redis that tests/services.py starts."""

from console.settings.base import *  # noqa: F403
from console.settings.base import DATABASES, VAR_DIR, env

SECRET_KEY = "test-only-secret-key-that-is-long-enough-to-be-realistic-0123456789"  # noqa: S105
DEBUG = False
# The suite's database is a file, so that the Celery worker and Daphne processes it starts see it.
DATABASES["default"]["TEST"] = {"NAME": str(env.path("PITLANE_TEST_DB", VAR_DIR / "test.sqlite3"))}
PASSWORD_HASHERS = ["django.contrib.auth.hashers.MD5PasswordHasher"]
STORAGES["staticfiles"] = {  # noqa: F405
    "BACKEND": "django.contrib.staticfiles.storage.StaticFilesStorage"
}
WHITENOISE_USE_FINDERS = True
STATIC_ROOT = None  # nothing is collected; WhiteNoise serves from the finders
MEDIA_ROOT = env.path("PITLANE_TEST_MEDIA", VAR_DIR / "test-media")
STORAGES["default"]["OPTIONS"]["location"] = MEDIA_ROOT  # noqa: F405
# Dead rollout workers are given up on sooner, so that the tests that kill them stay short.
PITLANE_ROLLOUT_SILENCE = 20
PITLANE_ROLLOUT_STARTUP = 60
# Watched evaluations and races (the browser tests watch them) run at 20 times real time.
PITLANE_WATCHED_SPEEDUP = 20
# Slow work (a sandbox run, a route file's check) run inside a transaction fails the test that
# ran it (common.transactions.outside_transaction), where production only logs it.
PITLANE_TRANSACTION_GUARD = True
# The suite's training worker has two processes (tests.conftest.TRAINERS) whatever this machine
# would train at once (console.sizing), and its pages count the free trainers as it has them.
PITLANE_TRAINERS = 2
