"""A policy that acts: the network the rollout workers and evaluations drive with.

Built from the model's settings and the environment's spaces, as the learner builds it, so the
learner's weights (safetensors) load into it by name. This module imports no Django: the sandbox
child imports it.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np
import torch

import simulator
from rl.hyperparameters import PPO
from rl.learner import load_weights, weights_bytes
from rl.networks import policy_kwargs


@dataclass
class Policy:
    """SB3's policy for ``algorithm`` with our network; ``weights_module`` is what the trainer
    publishes (PPO: the whole policy; SAC: the actor)."""

    algorithm: str
    network: torch.nn.Module
    weights_module: torch.nn.Module

    @classmethod
    def build(cls, algorithm: str, architecture: str, observation_space, action_space) -> Policy:
        """``architecture``: the model's network as ``networks.architecture`` names it."""
        kwargs = policy_kwargs(algorithm, architecture)
        spaces = (observation_space, action_space)
        if algorithm == PPO:
            from stable_baselines3.common.policies import MultiInputActorCriticPolicy

            policy = MultiInputActorCriticPolicy(*spaces, lambda _: 0.0, **kwargs)
            module = policy
        else:
            from stable_baselines3.sac.policies import MultiInputPolicy

            policy = MultiInputPolicy(*spaces, lambda _: 0.0, **kwargs)
            module = policy.actor
        policy.set_training_mode(False)
        return cls(algorithm, policy, module)

    @classmethod
    def for_environment(cls, algorithm: str, architecture: str, environment: dict) -> Policy:
        """The policy for the environment that ``environment`` (``gymnasium.make``'s keyword
        arguments) describes, built from its spaces."""
        env = gymnasium.make(simulator.ENV_ID, **environment)
        try:
            return cls.build(algorithm, architecture, env.observation_space, env.action_space)
        finally:
            env.close()

    @property
    def ppo(self) -> bool:
        return self.algorithm == PPO

    def load_published(self, data: bytes) -> None:
        """Weights as the trainer publishes them to the rollout workers."""
        load_weights(self.weights_module, data)

    def load_checkpoint(self, data: bytes) -> None:
        """A checkpoint (the policy with its critics), as the trainer stores it."""
        load_weights(self.network, data)

    def checkpoint(self) -> bytes:
        """The policy with its critics as the trainer stores a checkpoint."""
        return weights_bytes(self.network.state_dict())

    def act(
        self, observation: dict, deterministic: bool
    ) -> tuple[np.ndarray, float | None, float | None]:
        """(action, value, log-probability); value and log-probability only for PPO."""
        tensor, _ = self.network.obs_to_tensor(observation)
        with torch.no_grad():
            if self.ppo:
                actions, values, log_probs = self.network(tensor, deterministic=deterministic)
                return actions[0].numpy(), float(values[0]), float(log_probs[0])
            return self.network.actor(tensor, deterministic=deterministic)[0].numpy(), None, None

    def drive(self, observation: dict) -> np.ndarray:
        """The deterministic action alone, as evaluations drive: PPO's critic, a network of its
        own, is not run (it would double the time of a step)."""
        tensor, _ = self.network.obs_to_tensor(observation)
        with torch.inference_mode():
            if self.ppo:
                action = self.network.get_distribution(tensor).get_actions(deterministic=True)
            else:
                action = self.network.actor(tensor, deterministic=True)
        return action[0].numpy()

    @staticmethod
    def command(action: np.ndarray, discrete: bool):
        """What the environment takes for an action: an index, or the clipped vector."""
        return int(action) if discrete else np.clip(action, -1.0, 1.0)
