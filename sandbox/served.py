"""A policy served to a sandbox child by its worker: how a rollout infers on the GPU.

The sealed child cannot run CUDA (its address-space limit and seccomp forbid what the driver
does), nor should it: the driver is a large surface to put beside racers' code. So where the
worker's policy runs on the GPU, the child holds a ``ServedPolicy`` in its place, which the
cars' ``rl.episode.Fleet`` calls as it would the policy: each step it sends the worker the
observations of all the cars exploring in one message (``act``), and reads back their actions,
PPO's values and log-probabilities (``acted``). The worker's ``PolicyServer`` answers with the
real ``rl.policies.Policy`` on its device, after checking every array the child sent, and within
``ANSWER_TIMEOUT``. Each car keeps its random stream: the worker holds a ``torch.Generator`` per
car, seeded as the child's own would be (the child names it by its seed), so a car drives the
same episodes, step for step, with its policy served or in its child.

The child's side imports no torch: a child whose policy is served never loads it.
"""

from __future__ import annotations

import concurrent.futures
from collections.abc import Callable
from typing import Any

import numpy as np

from rl.experience import decode_array, encode_arrays
from rl.hyperparameters import PPO
from rl.wire import ProtocolError

ANSWER_TIMEOUT = 30.0  # [s] for the worker's policy to answer one step (its first run included)
CHILD_PATIENCE = ANSWER_TIMEOUT + 5.0  # [s] a child waits for the answer before it gives up
HOW = ("explore", "drive", "value")


class ServedPolicy:
    """What the child drives with where its worker serves the policy: ``rl.policies.Policy``'s
    methods that ``rl.episode.Fleet`` and the child call, each one message to the worker
    (``ask`` sends it and returns the worker's answer)."""

    def __init__(self, algorithm: str, ask: Callable[[dict], dict]) -> None:
        self.ppo = algorithm == PPO
        self.ask = ask

    @staticmethod
    def generator(seed: int) -> int:
        """The car's random stream, held by the worker: named by its seed."""
        return seed

    @staticmethod
    def command(action: np.ndarray, discrete: bool):
        """What the environment takes for an action (``Policy.command``'s, without torch)."""
        return int(action) if discrete else np.clip(action, -1.0, 1.0)

    def load_published(self, data: bytes) -> None:
        """Nothing: the worker loads the weights into the policy it serves."""

    def explore(
        self, observations: list[dict], generators: list[int]
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """``Policy.explore``'s answer for the cars seeded ``generators``, from the worker."""
        arrays = self._act("explore", observations, generators)
        return arrays["actions"], arrays.get("values"), arrays.get("log_probs")

    def drive(self, observation: dict) -> np.ndarray:
        return self._act("drive", [observation])["actions"][0]

    def value(self, observation: dict) -> float:
        return float(self._act("value", [observation])["values"][0])

    def _act(self, how: str, observations: list[dict], seeds: list[int] | None = None) -> dict:
        batch = {name: np.stack([seen[name] for seen in observations]) for name in observations[0]}
        answer = self.ask(
            {
                "type": "act",
                "how": how,
                "seeds": seeds,
                "observations": encode_arrays(batch, compress=False),  # 19 KB a car's camera
            }
        )
        # The worker is trusted: its arrays are taken as they say they are.
        return {
            name: decode_array(packed, packed["dtype"], tuple(packed["shape"]), compressed=False)
            for name, packed in answer["arrays"].items()
        }


class PolicyServer:
    """The worker's side: ``policy`` (an ``rl.policies.Policy``, on its device) answering a child
    whose ``cars`` are seeded ``seed`` + car. ``answer`` checks each request against the
    policy's observation space and the cars' seeds before the network sees it."""

    def __init__(self, policy: Any, seed: int, cars: int) -> None:
        self.policy = policy
        self.generators = {seed + car: policy.generator(seed + car) for car in range(cars)}
        self.spaces = policy.network.observation_space.spaces
        blank = {name: np.zeros(space.shape, space.dtype) for name, space in self.spaces.items()}
        policy.explore([blank] * cars, [None] * cars)  # the device made ready, as the child's
        self._runner = concurrent.futures.ThreadPoolExecutor(1, "served policy")

    @property
    def device(self) -> str:
        return str(self.policy.network.device)

    def answer(self, request: dict, timeout: float | None = None) -> dict:
        """The answer to a child's ``act`` request: {"arrays": ...}. ``ProtocolError`` for a
        request out of protocol; ``TimeoutError`` when the policy has not answered within
        ``timeout`` (a device that hangs); the policy's own errors (the device's) propagate."""
        how, observations, seeds = self._checked(request)
        timeout = ANSWER_TIMEOUT if timeout is None else timeout
        work = self._runner.submit(self._run, how, observations, seeds)
        try:
            return {"arrays": encode_arrays(work.result(timeout), compress=False)}
        except concurrent.futures.TimeoutError:
            raise TimeoutError(f"no answer in {timeout:g} s") from None

    def close(self) -> None:
        """Stop taking requests; one the device still runs is left to end alone."""
        self._runner.shutdown(wait=False, cancel_futures=True)

    def _run(self, how: str, observations: list[dict], seeds: list[int]) -> dict:
        if how == "drive":
            return {"actions": self.policy.drive(observations[0])[None]}
        if how == "value":
            return {"values": np.array([self.policy.value(observations[0])], dtype=np.float32)}
        generators = [self.generators[seed] for seed in seeds]
        actions, values, log_probs = self.policy.explore(observations, generators)
        arrays = {"actions": actions}
        if values is not None:
            arrays["values"], arrays["log_probs"] = values, log_probs
        return arrays

    def _checked(self, request: dict) -> tuple[str, list[dict], list[int]]:
        """(how, one observation per car, the cars' seeds) of ``request``, every part checked."""
        how, packed = request.get("how"), request.get("observations")
        if how not in HOW or not isinstance(packed, dict) or set(packed) != set(self.spaces):
            raise ProtocolError("a request for the policy that is not one")
        batch = {
            name: decode_array(
                packed[name], str(space.dtype), (None, *space.shape), compressed=False
            )
            for name, space in self.spaces.items()
        }
        if any(a.dtype.kind == "f" and not np.isfinite(a).all() for a in batch.values()):
            raise ProtocolError("observations that are not finite numbers")
        count = {len(array) for array in batch.values()}
        most = len(self.generators) if how == "explore" else 1
        if len(count) != 1 or not 1 <= (cars := count.pop()) <= most:
            raise ProtocolError("observations for no car, or for more than it has")
        seeds = request.get("seeds")
        if how == "explore" and (
            not isinstance(seeds, list)
            or len(seeds) != cars
            or not all(type(seed) is int and seed in self.generators for seed in seeds)
            or len(set(seeds)) != cars
        ):
            raise ProtocolError("seeds of no car it drives")
        return (
            how,
            [{name: array[car] for name, array in batch.items()} for car in range(cars)],
            seeds,
        )
