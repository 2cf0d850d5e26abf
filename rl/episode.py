"""The episode loop: a policy drives the environment from a reset to the episode's end.

One loop for every episode Pitlane drives: the sandbox child's training and evaluation episodes
(``sandbox.child``), an evaluation job's trials (``jobs.evaluation``) and what the sandbox's
benchmark times in process (``bench.bench_sandbox``). What differs between them is the mode and
what runs after the reset and after each step (``on_reset``, ``on_step``: trace rows, video and
live frames, lap records, progress), never the loop.

The loop drives a ``Fleet``: one car (``drive``) or several, each in an environment of its own
with an episode of its own, stepped together so that the policy runs once a step for all the
cars exploring (one batched forward pass, the costly part of a step). Each car draws its actions
from random streams of its own (``Policy.generator``, its action space's), so a car drives the
same episodes, step for step, whether it drives alone or beside others. Given a scorer
(``score``), a fleet asks the reward function for every car's reward in one call a step (the
sandbox's reward process answers it in one round trip); without one, each car's environment
calls its own ``reward_fn``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from simulator import head_to_head

if TYPE_CHECKING:  # the loop only calls the policy: a child that validates loads no torch
    from rl.policies import Policy

MODES = ("explore", "random", "evaluate")


@dataclass
class Driven:
    """An episode as driven. With ``record``, every observation (the first included), action,
    PPO's value and log-probability of it, and trace row (the prepare row first, as DeepRacer's
    trace has it); else the rewards and the last step's ``info`` alone."""

    mode: str = "explore"
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


@dataclass
class Car:
    """One of a fleet's cars: its environment, its own random stream for the policy's sampling,
    and the episode it drives (``mode`` None: it is idle; ``driven`` then holds its last one)."""

    env: Any
    index: int
    generator: Any = None  # a torch.Generator, or None for torch's global stream
    policy: Policy | None = None  # its own, where it evaluates another's (model against model)
    mode: str | None = None
    record: bool = True
    observation: dict | None = None
    driven: Driven = field(default_factory=Driven)


Score = Callable[[list[tuple[int, dict]]], list[float]]


class Fleet:
    """Cars driven together by one policy (a car that evaluates may have its own,
    ``Car.policy``: racers' models against each other, ``jobs.evaluation``). ``seeds[i]``
    seeds car ``i``'s sampling and its action space (their environments are seeded by their
    resets). ``score``, where given, takes each car's (index, params) of a step and gives their
    rewards, in one call for all the cars; a call that fails raises, naming the failing car's
    index in the exception's ``car`` where it knows it. With ``race``, the cars race on one
    track (``simulator.head_to_head``: each environment made with the others as its rivals):
    before each step every car learns where the others stand, a car whose episode is over
    parked off the field."""

    def __init__(
        self,
        envs: list,
        policy: Policy,
        seeds: list[int] | None = None,
        score: Score | None = None,
        race: bool = False,
    ) -> None:
        self.policy = policy
        self.score = score
        self.race = race
        self.cars: list[Car] = []
        self.stepping: Car | None = None  # the car whose step raised, when one did
        for index, env in enumerate(envs):
            seed = None if seeds is None else seeds[index]
            if seed is not None:
                env.action_space.seed(seed)
            generator = policy.generator(seed) if seed is not None and policy is not None else None
            self.cars.append(Car(env, index, generator))

    def driving(self) -> list[Car]:
        return [car for car in self.cars if car.mode is not None]

    def idle(self) -> list[Car]:
        return [car for car in self.cars if car.mode is None]

    def start(
        self, car: Car, mode: str, *, record: bool = True, seed: int | None = None
    ) -> tuple[dict, dict]:
        """Reset ``car``'s environment (with ``seed``) for an episode in ``mode``: "explore" (the
        policy, sampling), "random" (uniform actions) or "evaluate" (the policy,
        deterministic). The reset's observation and info."""
        if mode not in MODES:
            raise ValueError(f"An episode explores, drives at random or evaluates, not {mode!r}.")
        observation, info = car.env.reset(seed=seed)
        car.mode, car.record, car.observation = mode, record, observation
        car.driven = Driven(mode=mode)
        if record:
            car.driven.observations = {name: [value] for name, value in observation.items()}
            car.driven.trace.append(list(info["trace"]))
        return observation, info

    def step(self, on_step: Callable[[Car, dict, dict, bool], None] | None = None) -> list[Car]:
        """One step of every car that drives: their actions first (one forward pass for all
        that explore), then each car's environment steps in turn, ``on_step(car, observation,
        info, done)`` after each. The cars whose episodes ended, now idle with ``driven``
        whole. The reward function's failures propagate; the failing car (``stepping``) is
        left idle, its episode abandoned (with a scorer, every car of the step is: none of
        their steps can end without the rewards)."""
        if self.race:
            head_to_head.place_rivals(
                [car.env.unwrapped for car in self.cars],
                [car.mode is not None for car in self.cars],
            )
        driving = self.driving()
        chosen = self._actions(driving)
        if self.score is not None:
            return self._step_together(driving, chosen, on_step)
        finished = []
        for car, (action, value, log_prob) in zip(driving, chosen, strict=True):
            self.stepping = car
            try:
                outcome = car.env.step(self._command(car, action))
                done = self._record(car, action, value, log_prob, outcome, on_step)
            except BaseException:
                car.mode = None
                raise
            if done:
                finished.append(car)
        self.stepping = None
        return finished

    def _step_together(self, driving: list[Car], chosen: list[tuple], on_step) -> list[Car]:
        """``step`` with one call of the scorer for every car's reward: each car's environment
        advances to its reward params, the scorer gives all the rewards, then each concludes.
        Where the scorer fails, ``stepping`` is the car its exception names (None if none).
        The environments are stepped unwrapped (``DeepRacerEnv.advance`` and ``conclude``):
        what a wrapper's ``step`` adds is not run (Gymnasium's order check alone, in ours)."""
        advanced, self.stepping = [], None
        try:
            for car, (action, _value, _log_prob) in zip(driving, chosen, strict=True):
                self.stepping = car
                advanced.append(car.env.unwrapped.advance(self._command(car, action)))
            self.stepping = None
            calls = [
                (car.index, params)
                for car, params in zip(driving, advanced, strict=True)
                if params is not None
            ]
            rewards = iter(self.score(calls) if calls else [])
        except BaseException as error:
            if self.stepping is None:  # the scorer's failure
                named = getattr(error, "car", None)
                self.stepping = next((car for car in driving if car.index == named), None)
            for car in driving:
                car.mode = None
            raise
        finished = []
        for place, (car, params) in enumerate(zip(driving, advanced, strict=True)):
            self.stepping = car
            action, value, log_prob = chosen[place]
            try:
                outcome = car.env.unwrapped.conclude(None if params is None else next(rewards))
                done = self._record(car, action, value, log_prob, outcome, on_step)
            except BaseException:
                for unfinished in driving[place:]:  # their steps cannot end now
                    unfinished.mode = None
                raise
            if done:
                finished.append(car)
        self.stepping = None
        return finished

    def _actions(self, cars: list[Car]) -> list[tuple]:
        """(action, value, log-probability) for each of ``cars``."""
        chosen: dict[int, tuple] = {}
        exploring = [car for car in cars if car.mode == "explore"]
        if exploring:
            actions, values, log_probs = self.policy.explore(
                [car.observation for car in exploring], [car.generator for car in exploring]
            )
            for row, car in enumerate(exploring):
                chosen[car.index] = (
                    actions[row],
                    0.0 if values is None else float(values[row]),
                    0.0 if log_probs is None else float(log_probs[row]),
                )
        evaluating: dict[int, list[Car]] = {}  # by the policy they drive with
        for car in cars:
            if car.mode == "random":
                chosen[car.index] = (car.env.action_space.sample(), 0.0, 0.0)
            elif car.mode == "evaluate":
                evaluating.setdefault(id(self._policy(car)), []).append(car)
        for together in evaluating.values():  # one pass for the cars of a policy
            driven = self._policy(together[0]).drive_rows([car.observation for car in together])
            for row, car in enumerate(together):
                chosen[car.index] = (driven[row], 0.0, 0.0)
        return [chosen[car.index] for car in cars]

    def _command(self, car: Car, action):
        """What ``car``'s environment takes for ``action``."""
        return self._policy(car).command(action, hasattr(car.env.action_space, "n"))

    def _policy(self, car: Car) -> Policy:
        return car.policy or self.policy

    def _record(self, car: Car, action, value: float, log_prob: float, outcome, on_step) -> bool:
        """Record ``car``'s step (the environment's ``outcome`` of ``action``), then
        ``on_step``; whether its episode ended (the car is then idle)."""
        observation, reward, terminated, truncated, info = outcome
        driven = car.driven
        car.observation = observation
        driven.rewards.append(reward)
        driven.last_observation = observation
        if car.record:
            driven.actions.append(action)
            driven.values.append(value)
            driven.log_probs.append(log_prob)
            for name, value_now in observation.items():
                driven.observations[name].append(value_now)
            driven.trace.append(list(info["trace"]))
        done = bool(terminated or truncated)
        if on_step is not None:
            on_step(car, observation, info, done)
        if done:
            car.mode = None
            driven.info, driven.terminated, driven.truncated = (
                info,
                bool(terminated),
                bool(truncated),
            )
        return done


def drive(
    env,
    policy: Policy,
    mode: str = "explore",
    *,
    record: bool = True,
    seed: int | None = None,
    on_reset: Callable[[dict, dict], None] | None = None,
    on_step: Callable[[dict, dict, bool], None] | None = None,
) -> Driven:
    """One episode of ``env`` from a reset (with ``seed``), a fleet of one car: ``mode``
    "explore" (the policy, sampling), "random" (uniform actions) or "evaluate" (the policy,
    deterministic). ``on_reset(observation, info)`` runs after the reset,
    ``on_step(observation, info, done)`` after each step. The reward function's failures
    propagate."""
    fleet = Fleet([env], policy)
    car = fleet.cars[0]
    observation, info = fleet.start(car, mode, record=record, seed=seed)
    if on_reset is not None:
        on_reset(observation, info)
    stepped = None if on_step is None else (lambda _car, *seen: on_step(*seen))
    while not fleet.step(stepped):
        pass
    return car.driven


def experience(driven: Driven, discrete: bool, ppo: bool) -> dict[str, np.ndarray]:
    """A recorded episode's arrays as the trainer reads them: the observations (``obs:<name>``),
    actions and rewards, with PPO's values and log-probabilities of the actions."""
    arrays = {f"obs:{name}": np.stack(frames) for name, frames in driven.observations.items()}
    count = len(driven.actions)
    arrays["actions"] = (
        np.array(driven.actions, dtype=np.int64)
        if discrete
        else np.array(driven.actions, dtype=np.float32).reshape(count, -1)
    )
    arrays["rewards"] = np.array(driven.rewards, dtype=np.float32)
    if ppo:
        arrays["values"] = np.array(driven.values, dtype=np.float32)
        arrays["log_probs"] = np.array(driven.log_probs, dtype=np.float32)
    return arrays
