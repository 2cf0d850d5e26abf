"""The episode loop: a policy drives the environment from a reset to the episode's end.

One loop for every episode Pitlane drives: the sandbox child's training and evaluation episodes
(``sandbox.child``), an evaluation job's trials (``training.evaluation``) and what the sandbox's
benchmark times in process (``bench.bench_sandbox``). What differs between them is the mode and
what runs after the reset and after each step (``on_reset``, ``on_step``: trace rows, video and
live frames, lap records, progress), never the loop.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # the loop only calls the policy: a child that validates loads no torch
    from rl.policies import Policy

MODES = ("explore", "random", "evaluate")


@dataclass
class Driven:
    """An episode as driven. With ``record``, every observation (the first included), action,
    PPO's value and log-probability of it, and trace row (the prepare row first, as DeepRacer's
    trace has it); else the rewards and the last step's ``info`` alone."""

    rewards: list[float] = field(default_factory=list)
    observations: dict[str, list] = field(default_factory=dict)
    actions: list = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    log_probs: list[float] = field(default_factory=list)
    trace: list[list] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    terminated: bool = False
    truncated: bool = False
    last_observation: dict | None = None


def drive(
    env, policy: Policy, mode: str = "explore", *, record: bool = True, seed: int | None = None,
    on_reset: Callable[[dict, dict], None] | None = None,
    on_step: Callable[[dict, dict, bool], None] | None = None,
) -> Driven:  # fmt: skip
    """One episode of ``env`` from a reset (with ``seed``): ``mode`` "explore" (the policy,
    sampling), "random" (uniform actions) or "evaluate" (the policy, deterministic).
    ``on_reset(observation, info)`` runs after the reset, ``on_step(observation, info, done)``
    after each step. The reward function's failures propagate."""
    if mode not in MODES:
        raise ValueError(f"An episode explores, drives at random or evaluates, not {mode!r}.")
    discrete = hasattr(env.action_space, "n")
    observation, info = env.reset(seed=seed)
    if on_reset is not None:
        on_reset(observation, info)
    driven = Driven()
    if record:
        driven.observations = {name: [value] for name, value in observation.items()}
        driven.trace.append(list(info["trace"]))
    while True:
        if mode == "random":
            action, value, log_prob = env.action_space.sample(), 0.0, 0.0
        elif mode == "evaluate":
            action, value, log_prob = policy.drive(observation), 0.0, 0.0
        else:
            action, value, log_prob = policy.act(observation, deterministic=False)
        observation, reward, terminated, truncated, info = env.step(
            policy.command(action, discrete)
        )
        driven.rewards.append(reward)
        driven.last_observation = observation
        if record:
            driven.actions.append(action)
            driven.values.append(value or 0.0)
            driven.log_probs.append(log_prob or 0.0)
            for name, value_now in observation.items():
                driven.observations[name].append(value_now)
            driven.trace.append(list(info["trace"]))
        if on_step is not None:
            on_step(observation, info, terminated or truncated)
        if terminated or truncated:
            break
    driven.info, driven.terminated, driven.truncated = info, bool(terminated), bool(truncated)
    return driven


def experience(driven: Driven, discrete: bool, ppo: bool) -> dict[str, np.ndarray]:
    """A recorded episode's arrays as the trainer reads them: the observations (``obs:<name>``),
    actions and rewards, with PPO's values and log-probabilities of the actions."""
    arrays = {f"obs:{name}": np.stack(frames) for name, frames in driven.observations.items()}
    count = len(driven.actions)
    arrays["actions"] = (
        np.array(driven.actions, dtype=np.int64) if discrete
        else np.array(driven.actions, dtype=np.float32).reshape(count, -1)
    )  # fmt: skip
    arrays["rewards"] = np.array(driven.rewards, dtype=np.float32)
    if ppo:
        arrays["values"] = np.array(driven.values, dtype=np.float32)
        arrays["log_probs"] = np.array(driven.log_probs, dtype=np.float32)
    return arrays
