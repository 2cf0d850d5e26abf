"""The trainer's side of learning: a stable-baselines3 PPO or SAC fed from the experience buffer.

SB3 builds the policy (our DeepRacer networks as its features extractor), the optimiser and the
buffers; experience does not come from SB3's own rollout collection but from the rollout workers,
through Redis, one checked episode at a time. PPO's update is ours so that DeepRacer's choice of
value loss (Huber or MSE) is honoured; SAC's is SB3's. Weights go out as safetensors, never pickle.
"""

from __future__ import annotations

import functools
import json
import subprocess
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import gymnasium
import numpy as np
import stable_baselines3
import torch
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.buffers import DictRolloutBuffer
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import DummyVecEnv
from torch.nn import functional

from rl import hyperparameters as hp
from rl.experience import Episode
from rl.networks import policy_kwargs

GAE_LAMBDA = 0.95
CLIP_RANGE = 0.2
REPLAY_SIZE = 10_000  # [transitions] SAC's replay buffer
SAC_CHUNK = 32  # gradient steps between looks at whether the update should be abandoned

Progress = Callable[[int, int], None]
"""Told how far an update has gone: (gradient steps done, of the update's total), after each of
PPO's minibatches and each chunk of SAC's steps, the last call (total, total)."""


class Interrupted(Exception):
    """The update was abandoned part-way (the racer stopped training, or its time ran out); the
    model's weights are half-updated and must not be saved."""


class SpacesOnly(gymnasium.Env):
    """An environment that only has spaces: what SB3 needs to build a model that learns from
    experience collected elsewhere."""

    def __init__(self, observation_space, action_space) -> None:
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, *, seed=None, options=None):
        raise RuntimeError("experience comes from the rollout workers")

    def step(self, action):
        raise RuntimeError("experience comes from the rollout workers")


class DeepRacerPPO(PPO):
    """SB3's PPO with DeepRacer's update (rl_coach's ClippedPPO, as simapp configures it).

    Two things differ from SB3's ``PPO.train``: the advantages are standardised once over the
    whole batch, as rl_coach does (bundle/rl_coach/.../agents/clipped_ppo_agent.py:184-185,
    01f5f01), not per minibatch; and the value loss is Huber when DeepRacer's ``loss_type`` is
    "huber", mean squared error for anything else, "mse" included (simapp
    bundle/markov/sagemaker_graph_manager.py:139-140). SB3's options keep their meaning:
    ``normalize_advantage`` (False leaves the advantages as estimated), ``clip_range_vf`` (the
    value moves at most that far from the rollout's), ``target_kl`` (the update stops before a
    step whose minibatch is past 1.5 times it, from the policy the episodes were driven with),
    ``max_grad_norm``, ``ent_coef`` and ``vf_coef``.
    """

    def __init__(self, *args, value_loss: str = hp.HUBER, **kwargs) -> None:
        self.value_loss = value_loss
        self.interrupted: Callable[[], bool] = lambda: False  # looked at between minibatches
        self.progress: Progress = lambda done, total: None  # told after each minibatch
        super().__init__(*args, **kwargs)

    def train(self) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        if self.normalize_advantage:
            advantages = self.rollout_buffer.advantages
            advantages[:] = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        losses = []
        size = self.rollout_buffer.buffer_size * self.rollout_buffer.n_envs
        total = self.n_epochs * -(-size // self.batch_size)  # minibatches of all the epochs
        for done, batch in enumerate(self._minibatches()):
            if self.interrupted():
                raise Interrupted
            loss, terms, kl = self._loss(batch)
            if self.target_kl is not None and kl > 1.5 * self.target_kl:
                break
            self.policy.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
            losses.append(terms)
            self.progress(done + 1, total)
        if len(losses) < total:  # a target KL ended it early: it is done all the same
            self.progress(total, total)
        self.last_losses = dict(zip(("policy", "value", "entropy"), np.mean(losses, axis=0),
                                    strict=True)) if losses else {}  # fmt: skip

    def _minibatches(self) -> Iterator:
        """The rollout's minibatches, shuffled anew in each of ``n_epochs`` passes."""
        for _ in range(self.n_epochs):
            yield from self.rollout_buffer.get(self.batch_size)
            self._n_updates += 1

    def _loss(self, batch) -> tuple[torch.Tensor, tuple[float, float, float], float]:
        """(the loss of ``batch``, its policy, value and entropy terms, the approximate KL
        divergence of the policy from the one that drove)."""
        progress = self._current_progress_remaining
        actions = batch.actions
        if isinstance(self.action_space, gymnasium.spaces.Discrete):
            actions = actions.long().flatten()
        values, log_prob, entropy = self.policy.evaluate_actions(batch.observations, actions)
        values = values.flatten()
        log_ratio = log_prob - batch.old_log_prob
        ratio = torch.exp(log_ratio)
        clip = self.clip_range(progress)
        surrogate = torch.min(
            batch.advantages * ratio, batch.advantages * torch.clamp(ratio, 1 - clip, 1 + clip)
        )
        policy_loss = -surrogate.mean()
        if self.clip_range_vf is not None:
            reach = self.clip_range_vf(progress)
            values = batch.old_values + torch.clamp(values - batch.old_values, -reach, reach)
        value_loss = (
            functional.smooth_l1_loss if self.value_loss == hp.HUBER else functional.mse_loss
        )(values, batch.returns)
        entropy_loss = -(entropy if entropy is not None else -log_prob).mean()
        loss = policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
        with torch.no_grad():
            kl = float(((ratio - 1) - log_ratio).mean())
        return loss, (policy_loss.item(), value_loss.item(), entropy_loss.item()), kl


@dataclass
class Update:
    episodes: int
    steps: int
    reward: float  # average per episode
    completion: float  # average progress
    best_lap_time: float | None


class Learner:
    """One job's model: built from its settings, trained on episodes, saved as safetensors."""

    def __init__(
        self, *, algorithm: str, hyperparameters: dict, architecture: str,
        observation_space, action_space, seed: int = 0, device: str = "auto",
    ) -> None:  # fmt: skip
        self.algorithm = algorithm
        self.hyperparameters = hyperparameters
        self.seed = seed
        env = DummyVecEnv([lambda: SpacesOnly(observation_space, action_space)])
        kwargs = policy_kwargs(algorithm, architecture)
        h = hyperparameters
        if algorithm == hp.PPO:
            self.model = DeepRacerPPO(
                "MultiInputPolicy", env, n_steps=h["batch_size"], batch_size=h["batch_size"],
                n_epochs=h["num_epochs"], learning_rate=h["lr"], ent_coef=h["beta_entropy"],
                gamma=h["discount_factor"], gae_lambda=GAE_LAMBDA, clip_range=CLIP_RANGE,
                value_loss=h["loss_type"], policy_kwargs=kwargs, seed=seed, device=device,
            )  # fmt: skip
        else:
            self.model = SAC(
                "MultiInputPolicy", env, learning_rate=h["lr"], buffer_size=REPLAY_SIZE,
                learning_starts=0, batch_size=h["batch_size"], ent_coef=h["sac_alpha"],
                gamma=h["discount_factor"], policy_kwargs=kwargs, seed=seed, device=device,
            )  # fmt: skip
        # The job's metrics are ours: a logger that writes nothing (SB3's configure(None) would
        # leave an empty SB3-<time> folder in the temporary directory for every learner built).
        self.model.set_logger(Logger(folder=None, output_formats=[]))
        self.observation_space, self.action_space = observation_space, action_space

    @property
    def device(self) -> str:
        return str(self.model.device)

    # Weights

    def policy_weights(self) -> bytes:
        """What the rollout workers need to act: the whole policy (PPO) or the actor (SAC)."""
        module = self.model.policy if self.algorithm == hp.PPO else self.model.policy.actor
        return weights_bytes(module.state_dict())

    def checkpoint(self) -> bytes:
        """Everything needed to go on learning: the policy with its critics, and in the file's
        metadata what made it (``provenance``)."""
        return weights_bytes(self.model.policy.state_dict(), metadata=self.provenance())

    def provenance(self) -> dict[str, str]:
        """What a checkpoint was made with, written into it: the algorithm, the network's seed,
        the code (``code_version``) and the versions of PyTorch and stable-baselines3."""
        return {
            "algorithm": self.algorithm,
            "seed": str(self.seed),
            "code": code_version(),
            "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__,
        }

    def restore(self, checkpoint: bytes) -> None:
        load_weights(self.model.policy, checkpoint)

    # Learning

    def learn(
        self, episodes: list[Episode], interrupted: Callable[[], bool] = lambda: False,
        progress: Progress = lambda done, total: None,
    ) -> Update:  # fmt: skip
        """One policy update from ``episodes``. ``interrupted`` is asked between minibatches (or
        every few gradient steps): when it says True, the update is abandoned (``Interrupted``).
        ``progress(done, total)`` is told the gradient steps done after each (``Progress``): PPO
        takes ``num_epochs`` passes of equal numbers of minibatches, SAC one step per
        transition."""
        if self.algorithm == hp.PPO:
            self.model.interrupted, self.model.progress = interrupted, progress
            try:
                self._learn_ppo(episodes)
            finally:
                self.model.interrupted = lambda: False
                self.model.progress = lambda done, total: None
        else:
            self._learn_sac(episodes, interrupted, progress)
        laps = [e.lap_time for e in episodes if e.lap_time]
        return Update(
            episodes=len(episodes),
            steps=sum(e.steps for e in episodes),
            reward=float(np.mean([e.rewards.sum() for e in episodes])),
            completion=float(np.mean([e.progress for e in episodes])),
            best_lap_time=min(laps) if laps else None,
        )

    def _learn_ppo(self, episodes: list[Episode]) -> None:
        gamma = self.hyperparameters["discount_factor"]
        advantages, returns = [], []
        for episode in episodes:
            a = _gae(episode, gamma, GAE_LAMBDA)
            advantages.append(a)
            returns.append(a + episode.values)
        steps = sum(e.steps for e in episodes)
        model = self.model
        buffer = DictRolloutBuffer(
            steps, self.observation_space, self.action_space, device=model.device,
            gamma=gamma, gae_lambda=GAE_LAMBDA, n_envs=1,
        )  # fmt: skip
        for name in buffer.observations:
            buffer.observations[name][:, 0] = np.concatenate(
                [e.observations[name][:-1] for e in episodes]
            ).reshape(steps, *buffer.obs_shape[name])
        buffer.actions[:, 0] = np.concatenate([e.actions for e in episodes]).reshape(steps, -1)
        buffer.rewards[:, 0] = np.concatenate([e.rewards for e in episodes])
        buffer.values[:, 0] = np.concatenate([e.values for e in episodes])
        buffer.log_probs[:, 0] = np.concatenate([e.log_probs for e in episodes])
        buffer.advantages[:, 0] = np.concatenate(advantages)
        buffer.returns[:, 0] = np.concatenate(returns)
        starts = np.zeros(steps, dtype=np.float32)
        starts[np.cumsum([0] + [e.steps for e in episodes[:-1]])] = 1.0
        buffer.episode_starts[:, 0] = starts
        buffer.pos, buffer.full = steps, True
        model.rollout_buffer = buffer
        model._current_progress_remaining = 1.0
        model.train()

    def _learn_sac(
        self, episodes: list[Episode], interrupted: Callable[[], bool], progress: Progress
    ) -> None:
        model = self.model
        for episode in episodes:
            for t in range(episode.steps):
                done = t == episode.steps - 1 and episode.terminated
                model.replay_buffer.add(
                    {k: v[t][None] for k, v in episode.observations.items()},
                    {k: v[t + 1][None] for k, v in episode.observations.items()},
                    episode.actions[t][None],
                    episode.rewards[t : t + 1],
                    np.array([done]),
                    [{}],
                )
        gradient_steps = sum(e.steps for e in episodes)
        for done in range(0, gradient_steps, SAC_CHUNK):
            if interrupted():
                raise Interrupted
            chunk = min(SAC_CHUNK, gradient_steps - done)
            model.train(gradient_steps=chunk, batch_size=self.hyperparameters["batch_size"])
            progress(done + chunk, gradient_steps)


def _gae(episode: Episode, gamma: float, lam: float) -> np.ndarray:
    """Generalised advantage estimates of one episode, bootstrapped when it was truncated."""
    values, rewards = episode.values, episode.rewards
    next_values = np.append(values[1:], 0.0 if episode.terminated else episode.final_value)
    deltas = rewards + gamma * next_values - values
    advantages = np.zeros_like(rewards)
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        running = deltas[t] + gamma * lam * running
        advantages[t] = running
    return advantages


def weights_bytes(state: dict, metadata: dict[str, str] | None = None) -> bytes:
    """A state dict as safetensors, with ``metadata`` in its header; names that alias a tensor
    already saved are left out (PPO's policy reaches one features extractor by three names)."""
    seen, unique = set(), {}
    for name, tensor in state.items():
        pointer = (tensor.data_ptr(), tensor.dtype, tuple(tensor.shape))
        if pointer not in seen:
            seen.add(pointer)
            unique[name] = tensor.detach().cpu().contiguous()
    return save_tensors(unique, metadata=metadata)


def weights_metadata(data: bytes) -> dict[str, str]:
    """The metadata in the header of safetensors ``data`` (empty when it has none)."""
    size = int.from_bytes(data[:8], "little")
    if len(data) < 8 + size:
        raise ValueError("not a safetensors file")
    return json.loads(data[8 : 8 + size]).get("__metadata__") or {}


@functools.cache
def code_version() -> str:
    """The code running: Pitlane's version and, in a git checkout, its commit (``git
    describe``), marked "dirty" when the checkout has changes not committed."""
    root = Path(__file__).resolve().parent.parent
    version = tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]
    try:
        described = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--abbrev=12"],
            cwd=root, capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return version
    return f"{version}+{described.replace('-', '.')}" if described else version


def load_weights(module: torch.nn.Module, data: bytes) -> None:
    """Load safetensors ``data`` saved by ``weights_bytes`` into ``module``; every parameter must be
    there, under its own name or an alias of one."""
    tensors = load_tensors(data)
    missing, unexpected = module.load_state_dict(tensors, strict=False)
    if unexpected:
        raise ValueError(f"weights for another network: {unexpected[:3]}")
    state = module.state_dict()
    loaded = {(state[name].data_ptr(), state[name].dtype) for name in tensors if name in state}
    orphans = [
        name for name in missing if (state[name].data_ptr(), state[name].dtype) not in loaded
    ]
    if orphans:
        raise ValueError(f"weights missing for {orphans[:3]}")
