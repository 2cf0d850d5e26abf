"""The trainer's side of learning: a stable-baselines3 PPO or SAC fed from the experience buffer.

SB3 builds the policy (our DeepRacer networks as its features extractor), the optimiser and the
buffers; experience does not come from SB3's own rollout collection but from the rollout workers,
through Redis, one checked episode at a time. PPO's update is ours (rl.ppo) so that DeepRacer's
choice of value loss (Huber or MSE) is honoured; SAC's gradient step is SB3's, done with less work
(rl.sac). Weights go out as safetensors, never pickle.
"""

from __future__ import annotations

import functools
import json
import subprocess
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import gymnasium
import numpy as np
import stable_baselines3
import torch
from safetensors.torch import load as load_tensors
from safetensors.torch import save as save_tensors
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import DummyVecEnv

from rl import hyperparameters as hp
from rl.experience import Episode
from rl.graphed import GraphedStep
from rl.networks import lower_precision, policy_kwargs
from rl.ppo import DeepRacerPPO, Interrupted, Progress, Rollout
from rl.sac import DeepRacerSAC

PRECISIONS = ("fp32", "bf16", "auto")

GAE_LAMBDA = 0.95
CLIP_RANGE = 0.2
REPLAY_SIZE = 10_000  # [transitions] SAC's replay buffer
SAC_CHUNK = 32  # gradient steps between looks at whether the update should be abandoned


class SpacesOnly(gymnasium.Env):
    """An environment that only has spaces: what SB3 needs to build a model that learns from
    experience collected elsewhere."""

    def __init__(self, observation_space, action_space) -> None:
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, *, seed=None, options=None):
        raise RuntimeError("experience comes from the rollout workers")

    def step(self, action):
        raise RuntimeError("experience comes from the rollout workers")


@dataclass
class Update:
    episodes: int
    steps: int
    reward: float  # average per episode
    completion: float  # average progress
    best_lap_time: float | None


class Learner:
    """One job's model: built from its settings, trained on episodes, saved as safetensors.
    ``precision``: what its updates compute the features in (``update_precision``)."""

    @classmethod
    def for_model(cls, model, env, **options) -> Learner:
        """A learner for ``model``'s settings (its ``algorithm``, ``hyperparameters`` and
        ``architecture``: a racer's model) on ``env``'s spaces; ``options``: the rest."""
        return cls(
            algorithm=model.algorithm,
            hyperparameters=model.hyperparameters,
            architecture=model.architecture,
            observation_space=env.observation_space,
            action_space=env.action_space,
            **options,
        )

    def __init__(
        self,
        *,
        algorithm: str,
        hyperparameters: dict,
        architecture: str,
        observation_space,
        action_space,
        seed: int = 0,
        device: str = "auto",
        precision: str = "fp32",
    ) -> None:
        self.algorithm = algorithm
        self.hyperparameters = hyperparameters
        self.seed = seed
        env = DummyVecEnv([lambda: SpacesOnly(observation_space, action_space)])
        kwargs = policy_kwargs(algorithm, architecture)
        h = hyperparameters
        if algorithm == hp.PPO:
            self.model = DeepRacerPPO(
                "MultiInputPolicy",
                env,
                n_steps=h["batch_size"],
                batch_size=h["batch_size"],
                n_epochs=h["num_epochs"],
                learning_rate=h["lr"],
                ent_coef=h["beta_entropy"],
                gamma=h["discount_factor"],
                gae_lambda=GAE_LAMBDA,
                clip_range=CLIP_RANGE,
                value_loss=h["loss_type"],
                policy_kwargs=kwargs,
                seed=seed,
                device=device,
            )
        else:
            self.model = DeepRacerSAC(
                "MultiInputPolicy",
                env,
                learning_rate=h["lr"],
                replay_size=REPLAY_SIZE,
                learning_starts=0,
                batch_size=h["batch_size"],
                ent_coef=h["sac_alpha"],
                gamma=h["discount_factor"],
                policy_kwargs=kwargs,
                seed=seed,
                device=device,
            )
        # The job's metrics are ours: a logger that writes nothing (SB3's configure(None) would
        # leave an empty SB3-<time> folder in the temporary directory for every learner built).
        self.model.set_logger(Logger(folder=None, output_formats=[]))
        self.observation_space, self.action_space = observation_space, action_space
        self.precision = update_precision(precision, self.model.device)
        if algorithm == hp.PPO and self.model.device.type == "cuda":
            self.model.graphed = GraphedStep(self.model)  # 5.4 times the eager step there

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
        self,
        episodes: list[Episode],
        interrupted: Callable[[], bool] = lambda: False,
        progress: Progress = lambda done, total: None,
    ) -> Update:
        """One policy update from ``episodes``. ``interrupted`` is asked between minibatches (or
        every few gradient steps): when it says True, the update is abandoned (``Interrupted``).
        ``progress(done, total)`` is told the gradient steps done after each (``Progress``): PPO
        takes ``num_epochs`` passes of equal numbers of minibatches, SAC one step per
        transition."""
        with lower_precision(self.model.policy, self.precision):
            if self.algorithm == hp.PPO:
                self.model.interrupted, self.model.progress = interrupted, progress
                try:
                    self._learn_ppo(episodes)
                finally:
                    self.model.interrupted = lambda: False
                    self.model.progress = lambda done, total: None
                    self.model.rollout = None  # its frames: hundreds of MB on the device
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
        advantages = [_gae(episode, gamma, GAE_LAMBDA) for episode in episodes]
        returns = [a + episode.values for a, episode in zip(advantages, episodes, strict=True)]
        steps = sum(e.steps for e in episodes)
        device = self.model.device

        def column(arrays: list[np.ndarray], dtype=np.float32) -> torch.Tensor:
            return torch.as_tensor(np.concatenate(arrays).astype(dtype, copy=False)).to(device)

        self.model.rollout = Rollout(
            observations={
                name: column([e.observations[name][:-1] for e in episodes], space.dtype)
                for name, space in self.observation_space.spaces.items()
            },
            actions=column([e.actions for e in episodes]).reshape(steps, -1),
            values=column([e.values for e in episodes]),
            log_probs=column([e.log_probs for e in episodes]),
            advantages=column(advantages),
            returns=column(returns),
        )
        self.model._current_progress_remaining = 1.0
        self.model.train()

    def _learn_sac(
        self, episodes: list[Episode], interrupted: Callable[[], bool], progress: Progress
    ) -> None:
        model = self.model
        for episode in episodes:
            model.replay.add(episode)
        gradient_steps = sum(e.steps for e in episodes)
        for done in range(0, gradient_steps, SAC_CHUNK):
            if interrupted():
                raise Interrupted
            chunk = min(SAC_CHUNK, gradient_steps - done)
            model.train(gradient_steps=chunk, batch_size=self.hyperparameters["batch_size"])
            progress(done + chunk, gradient_steps)


def update_precision(precision: str, device: torch.device) -> torch.dtype | None:
    """What an update computes the features in: None (float32) for "fp32"; bfloat16 for "bf16",
    and for "auto" where ``device`` computes it natively (a GPU of compute capability 8 or more,
    not one that emulates it, slower than float32; a CPU with AVX-512 BF16 or AMX). The heads,
    losses, log-probabilities and optimiser stay float32 whatever it is, as do the rollouts."""
    if precision not in PRECISIONS:
        raise ValueError(
            f"the trainer's precision is one of {', '.join(PRECISIONS)}, not {precision!r}"
        )
    if precision == "auto":
        if device.type == "cuda":
            with torch.cuda.device(device):  # the learner's GPU, not the process's current one
                native = torch.cuda.is_bf16_supported(including_emulation=False)
        else:
            native = torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported()
        precision = "bf16" if native else "fp32"
    return torch.bfloat16 if precision == "bf16" else None


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
            cwd=root,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
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
