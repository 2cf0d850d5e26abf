"""SAC's gradient step, near the hardware: stable-baselines3's SAC with its replay buffer as
tensors on the learner's device and a step that does no work twice.

SB3's ``SAC.train`` is the reference, step for step (the same losses, the same order, the same
draws from torch's generator); what differs is where the time went on a camera model:

- the replay buffer is tensors on the device, filled a whole episode at a time and sampled there
  (SB3's copies each transition in from numpy, then each batch from numpy to the device);
- the actor's loss reads the critics' Q of the actor's actions with the critic's features of the
  observations taken without gradients: only the action's path to the actor matters to it, and
  SB3's went back through the critic's convolutions too, for gradients the critic's next
  ``zero_grad`` threw away;
- the target critic follows with one ``torch._foreach`` pass over its tensors, not one per tensor;
- no loss is read back to the host each step (``.item()``, a wait on a GPU).

What is left is arithmetic: with DeepRacer's 3-layer camera network (about 44 MFLOP a frame
forward, 129 with its backward) a gradient step of 64 runs the actor's and the critic's features
forward and back on the observations, the actor's and the target critic's forward on the next
ones and the critic's forward for the actor's loss: about 25 GFLOP (SB3's step 30), where PPO's
update is about 2.6 a step (10 epochs, two networks). On the dev box's 2 cores that measured
130 ms a step against PPO's 15.0 ms (bf16 features: 80 against 10.5; SB3's step 165 to 280 ms,
bench.bench_training --update --algorithm sac): twice PPO's is out of reach while DeepRacer's
SAC takes a step of 64 for every step driven.

DeepRacer's alpha is fixed (``sac_alpha``, rl_coach's SAC has no automatic entropy tuning:
agents/soft_actor_critic_agent.py), so SB3's entropy optimiser is never built; nor are SB3's
``target_update_interval`` other than 1 and ``use_sde`` followed: ``DeepRacerSAC`` refuses them.
"""

from __future__ import annotations

import numpy as np
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.type_aliases import DictReplayBufferSamples
from torch.nn import functional

from rl.experience import Episode


class Replay:
    """A bounded replay buffer of transitions as tensors on ``device``: the oldest are
    overwritten once it holds ``capacity``; sampled uniformly with a generator of its own."""

    def __init__(self, capacity: int, observation_space, action_dim: int, device, seed: int):
        self.capacity, self.device = capacity, torch.device(device)
        self.size = self.position = 0

        def frames(space) -> torch.Tensor:
            """Room for ``capacity`` observations, taking no memory until written (a camera's:
            10,000 frames of 19,200 bytes, twice); none is read past ``size``."""
            dtype = torch.from_numpy(np.zeros(0, dtype=space.dtype)).dtype
            return torch.empty((capacity, *space.shape), dtype=dtype, device=self.device)

        spaces = observation_space.spaces
        self.observations = {name: frames(space) for name, space in spaces.items()}
        self.next_observations = {name: frames(space) for name, space in spaces.items()}
        self.actions = torch.zeros((capacity, action_dim), device=self.device)
        self.rewards = torch.zeros((capacity, 1), device=self.device)
        self.dones = torch.zeros((capacity, 1), device=self.device)
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(seed)

    def add(self, episode: Episode) -> None:
        """Every transition of ``episode`` (of one longer than the buffer, the last ones); its
        last is done only when the episode ended there (a truncated one's last state is not
        terminal)."""
        steps = episode.steps
        kept = slice(max(0, steps - self.capacity), steps)
        done = np.zeros((steps, 1), dtype=np.float32)
        done[-1] = float(episode.terminated)
        columns = [
            *((self.observations[k], v[:-1]) for k, v in episode.observations.items()),
            *((self.next_observations[k], v[1:]) for k, v in episode.observations.items()),
            (self.actions, np.asarray(episode.actions, np.float32).reshape(steps, -1)),
            (self.rewards, np.asarray(episode.rewards, np.float32).reshape(steps, 1)),
            (self.dones, done),
        ]
        count = kept.stop - kept.start
        slots = (self.position + torch.arange(count, device=self.device)) % self.capacity
        for store, values in columns:
            store[slots] = torch.tensor(values[kept], device=self.device)  # decoded: read-only
        self.position = (self.position + count) % self.capacity
        self.size = min(self.size + count, self.capacity)

    def sample(self, batch_size: int) -> DictReplayBufferSamples:
        chosen = torch.randint(
            self.size, (batch_size,), device=self.device, generator=self.generator
        )
        return DictReplayBufferSamples(
            observations={k: v[chosen] for k, v in self.observations.items()},
            actions=self.actions[chosen],
            next_observations={k: v[chosen] for k, v in self.next_observations.items()},
            dones=self.dones[chosen],
            rewards=self.rewards[chosen],
        )


class DeepRacerSAC(SAC):
    """SB3's SAC with its gradient step as this module's docstring says, learning from
    ``replay`` (SB3's own buffer is built at one transition and never used)."""

    def __init__(self, *args, replay_size: int, **kwargs) -> None:
        super().__init__(*args, buffer_size=1, **kwargs)
        if self.ent_coef_optimizer is not None:
            raise ValueError("DeepRacer's SAC has a fixed alpha (sac_alpha), not 'auto'")
        if self.target_update_interval != 1:  # gradient_step follows them every time
            raise ValueError("DeepRacer's SAC updates its target critics every gradient step")
        if self.use_sde:  # no reset_noise between steps, as SB3's SAC.train would call
            raise ValueError("DeepRacer's SAC has no state-dependent exploration (use_sde)")
        action_dim = int(np.prod(self.action_space.shape))
        self.replay = Replay(
            replay_size, self.observation_space, action_dim, self.device, self.seed or 0
        )

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate([self.actor.optimizer, self.critic.optimizer])
        for _ in range(gradient_steps):
            self.gradient_step(self.replay.sample(batch_size))
        self._n_updates += gradient_steps

    def gradient_step(self, batch: DictReplayBufferSamples) -> None:
        """One step of the critics, the actor and the target critics on ``batch``, as SB3's
        ``SAC.train`` takes one."""
        alpha = self.ent_coef_tensor
        actions_pi, log_prob = self.actor.action_log_prob(batch.observations)
        with torch.no_grad():
            next_actions, next_log_prob = self.actor.action_log_prob(batch.next_observations)
            next_q = torch.cat(self.critic_target(batch.next_observations, next_actions), dim=1)
            next_q = next_q.min(dim=1, keepdim=True).values - alpha * next_log_prob.reshape(-1, 1)
            target_q = batch.rewards + (1 - batch.dones) * self.gamma * next_q
        current_q = self.critic(batch.observations, batch.actions)
        critic_loss = 0.5 * sum(functional.mse_loss(q, target_q) for q in current_q)
        self.critic.optimizer.zero_grad()
        critic_loss.backward()
        self.critic.optimizer.step()

        with torch.no_grad():  # the critic's features: the actor's loss needs no way through them
            features = self.critic.extract_features(
                batch.observations, self.critic.features_extractor
            )
        q_pi = torch.cat(
            [q(torch.cat([features, actions_pi], dim=1)) for q in self.critic.q_networks], dim=1
        )
        actor_loss = (alpha * log_prob.reshape(-1, 1) - q_pi.min(dim=1, keepdim=True).values).mean()
        self.actor.optimizer.zero_grad()
        actor_loss.backward()
        self.actor.optimizer.step()

        with torch.no_grad():  # SB3's polyak_update, over all the tensors at once
            targets = list(self.critic_target.parameters())
            torch._foreach_mul_(targets, 1 - self.tau)
            torch._foreach_add_(targets, list(self.critic.parameters()), alpha=self.tau)
            if self.batch_norm_stats:
                torch._foreach_copy_(self.batch_norm_stats_target, self.batch_norm_stats)
