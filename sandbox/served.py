"""The policy a sandbox child drives with where the machine's policy server serves it.

The sealed child cannot run CUDA (its address-space limit and seccomp forbid what the driver
does), nor should it: the driver is a large surface to put beside racers' code, and a copy of
the network in every child costs each its memory and its own small forward passes. So where a
rollout's policy is served (``PITLANE_ROLLOUT_DEVICE``), the child holds a ``ServedPolicy`` in
its place, which the cars' ``rl.episode.Fleet`` calls as it would the policy: each step it
writes the observations of all the cars exploring into its slots of the machine's policy server
(``rl.slots``) and reads back their actions, PPO's values and log-probabilities. The server
answers with the real ``rl.policies.Policy`` of the child's job and version, in one batched
forward pass with every other child driving it, after checking every row the child wrote. Each
car keeps its random stream: the server holds a ``torch.Generator`` per car, seeded as the
child's own would be (the child names it by its seed), so a car drives the same episodes, step
for step, with its policy served or in its child.

This module imports no torch: a child whose policy is served never loads it.
"""

from __future__ import annotations

import numpy as np

from rl.hyperparameters import PPO
from rl.slots import Layout, SlotClient

CHILD_PATIENCE = 35.0  # [s] a child waits for the server's answer to a step before it gives up


class ServedPolicy:
    """What the child drives with where the policy is served: ``rl.policies.Policy``'s methods
    that ``rl.episode.Fleet`` and the child call, each one round trip through the slots."""

    def __init__(self, algorithm: str, served: dict) -> None:
        self.ppo = algorithm == PPO
        self.slots = SlotClient(
            Layout.from_message(served["layout"]),
            int(served["memory_fd"]),
            int(served["socket_fd"]),
            float(served.get("patience", CHILD_PATIENCE)),
        )

    @property
    def socket_fd(self) -> int:
        return self.slots.socket_fd

    @staticmethod
    def generator(seed: int) -> int:
        """The car's random stream, held by the server: named by its seed."""
        return seed

    @staticmethod
    def command(action: np.ndarray, discrete: bool):
        """What the environment takes for an action (``Policy.command``'s, without torch)."""
        return int(action) if discrete else np.clip(action, -1.0, 1.0)

    def load_published(self, data: bytes) -> None:
        """Nothing: the worker gives the server the weights."""

    def explore(
        self, observations: list[dict], generators: list[int]
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """``Policy.explore``'s answer for the cars seeded ``generators``, from the server."""
        arrays = self.slots.act("explore", observations, generators)
        if not self.ppo:
            return arrays["actions"], None, None
        return arrays["actions"], arrays["values"], arrays["log_probs"]

    def drive_rows(self, observations: list[dict]) -> np.ndarray:
        """``Policy.drive_rows``'s answer: the evaluating cars' actions, from the server."""
        return self.slots.act("drive", observations, None)["actions"]

    def value(self, observation: dict) -> float:
        return float(self.slots.act("value", [observation], None)["values"][0])
