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
from stable_baselines3.common.distributions import SquashedDiagGaussianDistribution

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
    def build(
        cls,
        algorithm: str,
        architecture: str,
        observation_space,
        action_space,
        device: str = "cpu",
        *,
        loading: bool = False,
    ) -> Policy:
        """``architecture``: the model's network as ``networks.architecture`` names it;
        ``device``: where it runs (torch's name: "cpu", "cuda"); ``loading``: every weight is
        loaded next (``load_weights`` refuses a file that lacks one), so PPO's orthogonal
        initialisation, a QR decomposition of each extractor's dense layer (about 0.1 s each
        for DeepRacer's networks, thrown away at once), is skipped."""
        kwargs = policy_kwargs(algorithm, architecture)
        spaces = (observation_space, action_space)
        if algorithm == PPO:
            from stable_baselines3.common.policies import MultiInputActorCriticPolicy

            kwargs = {**kwargs, "ortho_init": not loading}
            policy = MultiInputActorCriticPolicy(*spaces, lambda _: 0.0, **kwargs)
            module = policy
        else:
            from stable_baselines3.sac.policies import MultiInputPolicy

            policy = MultiInputPolicy(*spaces, lambda _: 0.0, **kwargs)
            module = policy.actor
        policy.set_training_mode(False)
        policy.to(device)
        return cls(algorithm, policy, module)

    @classmethod
    def for_environment(
        cls,
        algorithm: str,
        architecture: str,
        environment: dict,
        device: str = "cpu",
        *,
        loading: bool = False,
    ) -> Policy:
        """The policy for the environment that ``environment`` (``gymnasium.make``'s keyword
        arguments) describes, built from its spaces, on ``device`` (``loading``: as ``build``)."""
        env = gymnasium.make(simulator.ENV_ID, **environment)
        try:
            spaces = (env.observation_space, env.action_space)
            return cls.build(algorithm, architecture, *spaces, device, loading=loading)
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

    def value(self, observation: dict) -> float:
        """PPO's critic's value of ``observation``, the critic alone run: an episode's last
        observation, where time cut it short."""
        tensor, _ = self.network.obs_to_tensor(observation)
        with torch.no_grad():
            return float(self.network.predict_values(tensor)[0])

    @staticmethod
    def generator(seed: int) -> torch.Generator:
        """A random stream of its own for one car's sampling (``explore``): a car's actions then
        depend on its seed alone, never on the cars it drives beside. On the CPU whatever the
        policy's device: a car draws the same actions from the same probabilities on either."""
        return torch.Generator().manual_seed(seed)

    def explore(
        self, observations: list[dict], generators: list[torch.Generator | None]
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Sampled actions for several cars in one forward pass, each car's drawn from its own
        generator (None: torch's global one): (actions, values, log-probabilities), the last
        two only for PPO, one row per car."""
        batch = {name: np.stack([seen[name] for seen in observations]) for name in observations[0]}
        tensor, _ = self.network.obs_to_tensor(batch)
        with torch.no_grad():
            if not self.ppo:
                actor = self.network.actor
                mean, log_std, kwargs = actor.get_action_dist_params(tensor)
                distribution = actor.action_dist.proba_distribution(mean, log_std, **kwargs)
                return _sample(distribution, generators).cpu().numpy(), None, None
            network = self.network  # SB3's ActorCriticPolicy.forward, its sampling apart
            features = network.extract_features(tensor)
            if network.share_features_extractor:
                latent_pi, latent_vf = network.mlp_extractor(features)
            else:
                latent_pi = network.mlp_extractor.forward_actor(features[0])
                latent_vf = network.mlp_extractor.forward_critic(features[1])
            values = network.value_net(latent_vf).flatten()
            distribution = network._get_action_dist_from_latent(latent_pi)
            actions = _sample(distribution, generators)
            log_probs = distribution.log_prob(actions)
        return actions.cpu().numpy(), values.cpu().numpy(), log_probs.cpu().numpy()

    def drive(self, observation: dict) -> np.ndarray:
        """The deterministic action alone, as evaluations drive: PPO's critic, a network of its
        own, is not run (it would double the time of a step)."""
        tensor, _ = self.network.obs_to_tensor(observation)
        with torch.inference_mode():
            if self.ppo:
                action = self.network.get_distribution(tensor).get_actions(deterministic=True)
            else:
                action = self.network.actor(tensor, deterministic=True)
        return action[0].cpu().numpy()

    @staticmethod
    def command(action: np.ndarray, discrete: bool):
        """What the environment takes for an action: an index, or the clipped vector."""
        return int(action) if discrete else np.clip(action, -1.0, 1.0)


def _sample(distribution, generators: list[torch.Generator | None]) -> torch.Tensor:
    """One action per row of ``distribution`` (SB3's categorical, Gaussian or squashed
    Gaussian), row ``i`` drawn from ``generators[i]``: the draw a row gets does not depend on the
    rows beside it. The draws are made on the CPU, where the generators are (the probabilities
    of a policy on the GPU brought over, a few numbers a car), and the actions go back."""
    inner = distribution.distribution
    if isinstance(inner, torch.distributions.Categorical):
        probs = inner.probs.cpu()
        return torch.cat(
            [
                torch.multinomial(probs[row], 1, generator=generator)
                for row, generator in enumerate(generators)
            ]
        ).to(inner.probs.device)
    noise = torch.stack(
        [torch.randn(inner.loc.shape[1:], generator=generator) for generator in generators]
    ).to(inner.loc.device)
    actions = inner.loc + inner.scale * noise
    if isinstance(distribution, SquashedDiagGaussianDistribution):
        distribution.gaussian_actions = actions
        return torch.tanh(actions)
    return actions
