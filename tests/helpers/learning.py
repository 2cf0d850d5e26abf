"""A learner over an environment, and episodes for it to learn from: random ones, shaped as a
rollout worker sends them, or as the learner's own policy would have driven them."""

import numpy as np
import torch

from rl import hyperparameters
from rl.experience import Episode
from rl.learner import Learner


def synthetic_episode(env, steps: int = 40) -> Episode:
    """An episode of random observations and actions, shaped as a rollout worker sends one."""
    observations = [env.observation_space.sample() for _ in range(steps + 1)]
    return Episode(
        worker=0,
        version=0,
        observations={
            name: np.stack([o[name] for o in observations]) for name in env.observation_space.spaces
        },
        actions=np.array([env.action_space.sample() for _ in range(steps)]),
        rewards=np.ones(steps, dtype=np.float32),
        values=np.zeros(steps, dtype=np.float32),
        log_probs=np.zeros(steps, dtype=np.float32),
        terminated=True,
        final_value=0.0,
        progress=10.0,
        status="off_track",
        lap_time=None,
        trace=[],
    )


def learner_for(env, algorithm: str = "clipped_ppo", **values) -> Learner:
    """A seeded learner (PPO unless ``algorithm`` says) for ``env``'s spaces, ``values`` over
    the default hyperparameters."""
    return Learner(
        algorithm=algorithm,
        hyperparameters={**hyperparameters.defaults(algorithm), **values},
        architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        observation_space=env.observation_space,
        action_space=env.action_space,
        seed=7,
    )


def driven(learner: Learner, env, steps: int = 48, scale: float = 1.0, offset: float = 0.0):
    """An episode as the learner's own policy would have driven it (so the first ratio is 1),
    with rewards ``scale`` times a fixed pattern; the values it was driven with are ``offset``
    from what the value network says now."""
    episode = synthetic_episode(env, steps=steps)
    episode.rewards = (scale * np.linspace(-1.0, 2.0, steps)).astype(np.float32)
    policy = learner.model.policy
    with torch.no_grad():
        observations = {
            name: torch.as_tensor(frames[:-1]) for name, frames in episode.observations.items()
        }
        observations, _ = policy.obs_to_tensor({k: v.numpy() for k, v in observations.items()})
        values, log_prob, _ = policy.evaluate_actions(
            observations, torch.as_tensor(episode.actions, dtype=torch.float32)
        )
    episode.values = (scale * values.flatten().numpy() + offset).astype(np.float32)
    episode.log_probs = log_prob.numpy().astype(np.float32)
    return episode


def steps_taken(learner: Learner) -> list:
    """A list that grows by one at each of the learner's optimiser steps."""
    taken = []
    learner.model.policy.optimizer.register_step_post_hook(lambda *_: taken.append(1))
    return taken
