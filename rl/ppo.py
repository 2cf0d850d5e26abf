"""DeepRacer's PPO update (rl_coach's ClippedPPO, as simapp configures it) on stable-baselines3's
PPO, learning from an update's episodes copied to the device at once (``Rollout``)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import gymnasium
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import DictRolloutBuffer
from stable_baselines3.common.type_aliases import DictRolloutBufferSamples
from torch.nn import functional

from rl import hyperparameters as hp

Progress = Callable[[int, int], None]
"""Told how far an update has gone: (gradient steps done, of the update's total), after each of
PPO's minibatches and each chunk of SAC's steps, the last call (total, total)."""


class Interrupted(Exception):
    """The update was abandoned part-way (the racer stopped training, or its time ran out); the
    model's weights are half-updated and must not be saved."""


@dataclass
class Rollout:
    """An update's episodes as tensors on the learner's device, copied there once: the frames as
    the cars saw them (bytes), and per step the action, the value and log-probability it was
    driven with, its advantage and its return."""

    observations: dict[str, torch.Tensor]
    actions: torch.Tensor  # (steps, 1) for a discrete action space, as SB3 stores them
    values: torch.Tensor
    log_probs: torch.Tensor
    advantages: torch.Tensor
    returns: torch.Tensor

    @property
    def size(self) -> int:
        return len(self.values)

    def minibatch(self, indices: torch.Tensor) -> DictRolloutBufferSamples:
        return DictRolloutBufferSamples(
            observations={name: frames[indices] for name, frames in self.observations.items()},
            actions=self.actions[indices],
            old_values=self.values[indices],
            old_log_prob=self.log_probs[indices],
            advantages=self.advantages[indices],
            returns=self.returns[indices],
        )


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

    Its minibatches are cut from ``rollout``, the whole update's experience copied to the
    device once, rather than from SB3's rollout buffer, which copies each minibatch from numpy
    (float32 frames, four times the bytes) to the device; in the same order, from the same
    shuffles (numpy's global generator, as SB3's), so the update is the same.
    """

    def __init__(self, *args, value_loss: str = hp.HUBER, **kwargs) -> None:
        self.value_loss = value_loss
        self.interrupted: Callable[[], bool] = lambda: False  # looked at between minibatches
        self.progress: Progress = lambda done, total: None  # told after each minibatch
        self.rollout: Rollout | None = None
        # PPO's minibatch step as a CUDA graph (rl.graphed.GraphedStep), which the learner sets on
        # a GPU; it reads no KL back between steps, so never with a target KL
        self.graphed = None
        super().__init__(*args, **kwargs)

    def train(self) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        if self.normalize_advantage:
            advantages = self.rollout.advantages
            advantages[:] = (advantages - advantages.mean()) / (advantages.std(correction=0) + 1e-8)
        losses = []
        total = self.n_epochs * -(-self.rollout.size // self.batch_size)  # of all the epochs
        for done, batch in enumerate(self._minibatches()):
            if self.interrupted():
                raise Interrupted
            terms = self._step(batch)
            if terms is None:
                break
            losses.append(terms)
            self.progress(done + 1, total)
        if len(losses) < total:  # a target KL ended it early: it is done all the same
            self.progress(total, total)
        if not losses:  # stopped before its first minibatch: the episodes were far off-policy
            self.last_losses = {}
            return
        means = torch.stack(losses).mean(dim=0).tolist()  # read once, at the end
        self.last_losses = dict(zip(("policy", "value", "entropy"), means, strict=True))

    def _step(self, batch) -> torch.Tensor | None:
        """One gradient step on ``batch``: its loss terms, or None where a target KL ends the
        update before it. Replayed from a CUDA graph where the learner has one (``graphed``)."""
        if self.graphed is not None:
            return self.graphed.step(batch)
        loss, terms, kl = self._loss(batch)
        if self.target_kl is not None and float(kl) > 1.5 * self.target_kl:
            return None
        self.policy.optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
        self.policy.optimizer.step()
        return terms

    def _minibatches(self) -> Iterator:
        """The rollout's minibatches, shuffled anew in each of ``n_epochs`` passes."""
        size = self.rollout.size
        for _ in range(self.n_epochs):
            shuffled = torch.as_tensor(np.random.permutation(size), device=self.device)
            for start in range(0, size, self.batch_size):
                yield self.rollout.minibatch(shuffled[start : start + self.batch_size])
            self._n_updates += 1

    def _loss(self, batch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(the loss of ``batch``, its policy, value and entropy terms, the approximate KL
        divergence of the policy from the one that drove); tensors, none read back to the host
        here (on a GPU each read waits for the device)."""
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
            kl = ((ratio - 1) - log_ratio).mean()
            terms = torch.stack([policy_loss, value_loss, entropy_loss])
        return loss, terms, kl


def sb3_minibatches(model: DeepRacerPPO) -> Iterator[DictRolloutBufferSamples]:
    """``model``'s minibatches as they were cut before its rollout went to the device at once:
    SB3's rollout buffer (float32 frames), each minibatch copied from numpy to the device, from
    the same shuffles. The reference the update is checked against (tests/rl/test_learner.py)
    and timed against (bench/bench_training.py --update)."""
    rollout = model.rollout
    buffer = DictRolloutBuffer(
        rollout.size, model.observation_space, model.action_space, device=model.device, n_envs=1
    )
    for name, frames in rollout.observations.items():
        buffer.observations[name][:, 0] = frames.cpu().numpy()
    buffer.actions[:, 0] = rollout.actions.cpu().numpy()
    for column in ("values", "log_probs", "advantages", "returns"):
        getattr(buffer, column)[:, 0] = getattr(rollout, column).cpu().numpy()
    buffer.full = True
    for _ in range(model.n_epochs):
        yield from buffer.get(model.batch_size)
