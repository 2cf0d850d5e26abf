"""Fixtures of the learner's tests: the environment they learn in."""

import gymnasium
import pytest

import simulator

CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2}}


@pytest.fixture(scope="module")
def env():
    """The Pitlane Oval with continuous actions, one a module."""
    environment = gymnasium.make(simulator.ENV_ID, track="pitlane-oval", action_space=CONTINUOUS)
    yield environment
    environment.close()
