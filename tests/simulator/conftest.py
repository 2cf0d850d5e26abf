import gymnasium
import pytest

import simulator
from simulator import tracks
from simulator.controller import CentreLineDriver

CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.1, "high": 4.0}}


@pytest.fixture(autouse=True)
def _no_track_resolvers(monkeypatch):
    """The simulator knows no Django: its tests run without the resolver the training app
    registers (which reads the database) when pytest-django sets the app up."""
    monkeypatch.setattr(tracks, "_resolvers", [])


def make(**settings):
    return gymnasium.make(simulator.ENV_ID, **settings)


def drive(env, driver=None, *, steps: int | None = None, until: str | None = None):
    """Step ``env`` with ``driver`` (the centre-line driver by default) until the episode ends,
    ``steps`` have passed or the status is ``until``; every step's info."""
    driver = driver or CentreLineDriver(env.unwrapped, speed=1.5)
    infos = []
    while steps is None or len(infos) < steps:
        _, _, terminated, truncated, info = env.step(driver.act())
        infos.append(info)
        if terminated or truncated or info["status"] == until:
            break
    return infos


@pytest.fixture
def environments():
    made = []

    def factory(**settings):
        env = make(**settings)
        made.append(env)
        return env

    yield factory
    for env in made:
        env.close()
