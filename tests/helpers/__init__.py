"""What more than one test module uses, by concern; a helper that one module uses stays in it.

- ``accounts``: the suite's password, and ``racer``, which makes conftest's named racers.
- ``browser``: a racer's steps in Chromium (log in, sign up) and the live frame's bytes.
- ``models``: models in the states tests need, made directly rather than through a training run.
- ``league``: the test season, its events, scored submissions and race evaluations.
- ``training``: a model's settings and the create-model form; training jobs, and waiting on one.
- ``training_logs``: a job's logs recorded on paper, and read back by deepracer-utils.
- ``archives``: DeepRacer exports, virtual-model and car archives, as racers upload them.
- ``evaluations``: an evaluation's stored files and its trials' paths.
- ``live``: websocket viewers of the live streams, and the frames they receive.
- ``sandbox``: reward functions run in the sandbox, and sandboxes that drive.
- ``learning``: a learner over an environment, and episodes for it to learn from.
- ``rollouts``: stand-ins for what a rollout worker drives with.
- ``analysis``: a trace written by hand and recorded as a job's, and a reward function for it.
- ``tracks``: route files and the admin's upload of one.
- ``private_files``: var/ as an install from before left it, and reads tried as another user.

Fixtures shared by a folder's modules are in its conftest.py (``env`` in tests/rl,
``admin_client`` in tests/training), not here.
"""

import pkgutil

import pytest

# pytest explains the failed asserts of test modules only, unless told of others: these modules
# are named before any is imported (this package itself is already, and has no asserts).
pytest.register_assert_rewrite(*(f"{__name__}.{m.name}" for m in pkgutil.iter_modules(__path__)))
