"""``make run``'s settings without the web tier, for bench/bench_pipeline.py's Celery workers:
Daphne (and the Twisted stack it imports with its app) is left out, so the workers run where
only the rollouts' and the trainer's packages are installed (the device machine's carried wheels).

``PITLANE_BENCH_UPDATE=stub`` (``bench_pipeline --update stub``): a trainer's PPO update learns
nothing, so an iteration is the pipeline's fixed costs and driving alone.
"""

import os

from console.settings.dev import *  # noqa: F403
from console.settings.dev import INSTALLED_APPS

INSTALLED_APPS = [app for app in INSTALLED_APPS if app != "daphne"]

if os.environ.get("PITLANE_BENCH_UPDATE") == "stub":
    from rl.learner import Learner

    Learner._learn_ppo = lambda self, episodes: None
