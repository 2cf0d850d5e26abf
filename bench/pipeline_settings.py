"""``make run``'s settings without the web tier, for bench/bench_pipeline.py's Celery workers:
Daphne (and the Twisted stack it imports with its app) is left out, so the workers run where
only the rollouts' and the trainer's packages are installed (the device machine's carried wheels).
"""

from console.settings.dev import *  # noqa: F403
from console.settings.dev import INSTALLED_APPS

INSTALLED_APPS = [app for app in INSTALLED_APPS if app != "daphne"]
