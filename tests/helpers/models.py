"""Models in the states tests need, made directly rather than through a training run."""

from __future__ import annotations

from pathlib import Path

import gymnasium
import numpy as np
import torch
from django.core.files.storage import default_storage

import simulator
from rl import hyperparameters
from rl.learner import Learner
from simulator.controller import CentreLineDriver
from training import artifacts, configuration
from training.models import RLModel, TrainingJob
from training.rewards import EXAMPLES

STRAIGHT_AHEAD = [
    {"steering_angle": -20.0, "speed": 4.0},
    {"steering_angle": 0.0, "speed": 4.0},
    {"steering_angle": 20.0, "speed": 4.0},
]


def ready_model(owner, name: str = "straight-ahead", track: str = "pitlane-oval") -> RLModel:
    """A READY model with one checkpoint whose policy always chooses to drive straight at 4 m/s:
    on a loop it leaves the track at each bend and is put back, so it finishes its laps, with
    penalties, in a predictable number of steps."""
    return trained_model(
        owner, name, weights=_straight_ahead, track=track, action_space=STRAIGHT_AHEAD
    )


def _straight_ahead(learner: Learner) -> None:
    head = learner.model.policy.action_net
    with torch.no_grad():
        head.weight.zero_()
        head.bias.copy_(torch.tensor([0.0, 10.0, 0.0]))


def trained_model(owner, name: str, *, weights=None, **settings) -> RLModel:
    """A READY model with one checkpoint: the learner's first weights (seeded), changed by
    ``weights(learner)`` when given. ``settings``: the model's, over the defaults."""
    settings = {
        "name": name,
        "track": "pitlane-oval",
        "hyperparameters": hyperparameters.defaults(settings.get("algorithm", "clipped_ppo")),
        "reward_function": EXAMPLES[0].source,
        **settings,
    }
    layout = settings.pop("network_layout", None)  # not a racer's setting
    clean = configuration.check(settings, owner=owner, validate_reward=False)
    if layout is not None:
        clean = clean.replace(network_layout=layout)
    model = RLModel.objects.create(owner=owner, status=RLModel.Status.READY, **clean.row())
    checkpoint = _first_checkpoint(model, weights)
    name = artifacts.save(model, "checkpoints/iteration-1.safetensors", checkpoint)
    TrainingJob.objects.create(
        model=model,
        status=TrainingJob.Status.COMPLETED,
        iterations=1,
        weights_version=1,
        last_checkpoint=name,
        best_checkpoint=name,
    )
    artifacts.write_model_files(model)
    return model


_CHECKPOINTS: dict[tuple, bytes] = {}
_KEPT = 8  # kinds of model (a camera's checkpoint is 47 MB): the test process stays small


def _first_checkpoint(model: RLModel, weights) -> bytes:
    """The learner's first weights for ``model``'s settings, changed by ``weights(learner)``:
    the same bytes each time, so built once a session (a learner takes about a second). The key
    holds ``weights`` itself, so a function's address is never taken by another while cached."""
    settings = (model.algorithm, model.architecture, model.hyperparameters, model.seed)
    key = (repr(settings), repr(model.environment_settings()), weights)
    if key not in _CHECKPOINTS:
        env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
        learner = Learner.for_model(model, env, seed=model.seed)
        env.close()
        if weights is not None:
            weights(learner)
        while len(_CHECKPOINTS) >= _KEPT:
            del _CHECKPOINTS[next(iter(_CHECKPOINTS))]  # the first built
        _CHECKPOINTS[key] = learner.checkpoint()
    return _CHECKPOINTS[key]


def sensor_frames(environment: dict, count: int = 12) -> list[dict]:
    """What the car's sensors see along the track (``environment``: ``gymnasium.make``'s keyword
    arguments): ``count`` observations a few steps apart, the centre-line driver at the wheel with
    one action in three a random one, so the views run round the track and off its line."""
    env = gymnasium.make(simulator.ENV_ID, **environment)
    observation, _ = env.reset(seed=3)
    env.action_space.seed(7)  # the same frames every run, whatever ran before
    driver = CentreLineDriver(env.unwrapped, speed=1.5)
    seen = []
    rng = np.random.default_rng(7)
    while len(seen) < count:
        for _ in range(4):
            action = env.action_space.sample() if rng.random() < 1 / 3 else driver.act()
            observation, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                observation, _ = env.reset(seed=int(rng.integers(1000)))
        seen.append(observation)
    env.close()
    return seen


def with_a_later_checkpoint(model: RLModel, number: int = 2) -> RLModel:
    """``model`` trained on to iteration ``number`` with its first weights again: its best
    checkpoint stays iteration 1, its last is iteration ``number``."""
    job = model.jobs.get()
    weights = artifacts.read(job.best_checkpoint)
    name = artifacts.save(model, artifacts.checkpoint(number), weights)
    TrainingJob.objects.filter(pk=job.pk).update(
        iterations=number, weights_version=number, last_checkpoint=name
    )
    return model


def stored_objects() -> set[str]:
    """Every file in the storage the code writes to (a test that counts them asks for the
    ``own_storage`` fixture, so that no other test's files come and go meanwhile)."""
    root = Path(default_storage.location)
    return {str(path.relative_to(root)) for path in root.rglob("*") if path.is_file()}
