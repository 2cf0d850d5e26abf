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
from stable_baselines3.common.policies import BaseModel

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
        actions, values, log_probs, _ = self.act(observations, generators)
        return actions, values, log_probs

    def act(
        self,
        observations: list[dict],
        generators: list[torch.Generator | None],
        driven: list[dict] = (),
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray]:
        """``explore``'s answer for ``observations`` and, in the same pass, ``drive``'s for the
        cars that evaluate (``driven``): (sampled actions, values, log-probabilities, driven
        actions). Their rows share the actor's pass, whose weights are read once for all: on a
        CPU the dense layer's 23 MB are most of a small pass, and an evaluating car alone pays
        them again for one row. The critic runs on the sampled rows only."""
        seen = [*observations, *driven]
        batch = {name: np.stack([each[name] for each in seen]) for name in seen[0]}
        tensor, _ = self.network.obs_to_tensor(batch)
        sampled = len(observations)
        actions = values = log_probs = deterministic = None
        with torch.no_grad():
            # SB3 keeps a pass's distribution on the policy's module: the sampled rows' is used
            # up before the driven rows' takes its place
            if not self.ppo:
                actor = self.network.actor
                mean, log_std, kwargs = actor.get_action_dist_params(tensor)
                distribution = actor.action_dist.proba_distribution
                if sampled:
                    actions = _sample(
                        distribution(mean[:sampled], log_std[:sampled], **kwargs), generators
                    )
                if driven:
                    deterministic = distribution(mean[sampled:], log_std[sampled:], **kwargs).mode()
            else:
                network = self.network  # SB3's ActorCriticPolicy.forward, its sampling apart
                latent_pi, latent_vf = self._latents(tensor, sampled)
                if sampled:
                    values = network.value_net(latent_vf).flatten().cpu().numpy()
                    distribution = network._get_action_dist_from_latent(latent_pi[:sampled])
                    actions = _sample(distribution, generators)
                    log_probs = distribution.log_prob(actions).cpu().numpy()
                if driven:
                    distribution = network._get_action_dist_from_latent(latent_pi[sampled:])
                    deterministic = distribution.mode()
        actions = (deterministic[:0] if actions is None else actions).cpu().numpy()
        deterministic = actions[:0] if deterministic is None else deterministic.cpu().numpy()
        return actions, values, log_probs, deterministic

    def _latents(self, tensor: dict, sampled: int) -> tuple[torch.Tensor, torch.Tensor | None]:
        """PPO's actor latents of every row, and its critic's of the first ``sampled``."""
        network = self.network
        if network.share_features_extractor:
            latent_pi, latent_vf = network.mlp_extractor(network.extract_features(tensor))
            return latent_pi, latent_vf[:sampled]
        features = BaseModel.extract_features(network, tensor, network.pi_features_extractor)
        latent_pi = network.mlp_extractor.forward_actor(features)
        if not sampled:
            return latent_pi, None
        critic_rows = {name: rows[:sampled] for name, rows in tensor.items()}
        features = BaseModel.extract_features(network, critic_rows, network.vf_features_extractor)
        return latent_pi, network.mlp_extractor.forward_critic(features)

    def drive(self, observation: dict) -> np.ndarray:
        """The deterministic action alone, as evaluations drive: PPO's critic, a network of its
        own, is not run (it would double the time of a step). ``act``'s driven row: the same
        pass as an evaluating car's served beside the training cars."""
        return self.drive_rows([observation])[0]

    def drive_rows(self, observations: list[dict]) -> np.ndarray:
        """``drive``'s actions for several evaluating cars, one row each, in one pass."""
        return self.act([], [], observations)[3]

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
