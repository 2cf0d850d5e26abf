"""Pitlane's simulator: tracks, the car, its sensors and the DeepRacer-compatible environment.

Pure Python: this package never imports Django; the apps call into it. Importing it registers the
Gymnasium environment ``Pitlane/DeepRacer-v0``.
"""

import gymnasium

ENV_ID = "Pitlane/DeepRacer-v0"

if ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=ENV_ID,
        entry_point="simulator.env:DeepRacerEnv",
        max_episode_steps=None,  # the environment truncates itself at time_up
        disable_env_checker=True,  # checked once in the test suite, not on every make()
    )
