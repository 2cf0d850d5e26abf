"""The sandbox child: forked for ``Sandbox`` by its worker process's zygote (``zygote.py``), which
runs ``main`` as ``python -s -m sandbox.child`` would.

It reads requests on standard input and answers on standard output, in protocol frames. It runs
only our code: it forks the reward process (``reward.py``), where the racer's code will run
alone, then builds the simulator (an environment per car: a rollout's child drives ``cars``
together, ``rl.episode.Fleet``) and the policy when a rollout is to drive (or places the car
in the sample situations a validation tries the code on), then seals itself (``seal.py``). Every
call of the racer's code goes to the reward process and is timed from here; what it prints
becomes log messages, what it raises, returns or takes too long over becomes an error message
naming the line. Since the racer's code cannot write to the worker, the frames the worker reads
(progress above all) are this module's. This module never imports Django.

Long because the child is one sealed process with one request loop: each request it answers
(validate, drive, serve a policy, sample situations) shares the seal and the reward process.
"""

from __future__ import annotations

import contextlib
import os
import select
import sys
import time
import traceback
from collections import deque
from typing import Any

import cv2
import msgpack

from rl import episode
from rl.slots import SlotsFailed
from rl.wire import encode_arrays
from sandbox import seal, served
from sandbox.protocol import pack, read_frame
from sandbox.reward import RewardFailure, RewardProcess
from simulator.config import VIEWS
from simulator.rewards import RewardError
from simulator.spectator import FRAME_INTERVAL, jpeg, view_image
from simulator.world import WorldUnavailable

PROGRESS_EVERY = 0.25  # [s] between progress messages during a rollout
LOOK_EVERY = 0.05  # [s] between looks for a watch request during an episode


class Child:
    def __init__(self) -> None:
        # Unbuffered: a watch request that comes during an episode must be seen by poll(), not
        # sit in a buffer read ahead of it.
        self.requests = os.fdopen(0, "rb", buffering=0)
        self._requests_ready = select.poll()
        self._requests_ready.register(0, select.POLLIN)
        self.views: set[str] = set()
        self.observation: dict | None = None  # the newest, for views drawn between episodes
        self.worker = 0
        self._last_look = self._last_frame = 0.0
        self.reply_fd = 1
        self.reward: RewardProcess | None = None
        self.env = None  # the shown car's: the lowest-numbered that drives (car 0 at first)
        self.envs: list = []
        self.fleet: episode.Fleet | None = None
        self.finished: deque[episode.Car] = deque()  # ended on one step, not yet sent
        self.driven = 0  # steps driven by all the cars, for progress messages
        self.episodes = 0  # episodes this worker's cars have started, the live view's numbers
        self.episode_of: dict[int, int] = {}  # each car's: the number of its episode
        self.shown_episode = 0  # the number of the shown car's episode
        self.policy = None
        self.ppo = True
        self.samples: list[dict] = []

    def send(self, message: dict[str, Any], *, log: bool = False) -> None:
        """Send ``message``; with ``log``, and what the reward process printed since the last."""
        if log and self.reward is not None:
            message["log"], message["log_dropped"] = self.reward.printed.take()
        data = pack(message)
        while data:
            data = data[os.write(self.reply_fd, data) :]

    def run(self) -> None:
        init = read_frame(self.requests)
        if init is None:
            return
        # Before anything else: the reward process, forked while this one is still small and
        # has no threads; then the simulator and the policy, which it never sees. The racer's
        # code gets the allowance alone, however many cars: only this process grows with them.
        self.reward = RewardProcess(float(init["call_timeout"]), int(init["memory_allowance"]))
        cv2.setNumThreads(0)  # no worker threads: the sealed process cannot start any
        cars = int(init.get("cars", 1))
        try:
            if init.get("env") is not None:
                self.envs = self._build_envs(init["env"], cars, bool(init.get("in_turn")))
                self.env = self.envs[0]
            if init.get("policy") is not None:
                self._build_policy(init["policy"])
            if init.get("samples") is not None:
                self.samples = _situations(init["samples"])
        except WorldUnavailable as error:  # a box within the lidar's reach at a reset
            self.send(_unavailable(error))
            return
        self.reward.wait_ready(60.0)
        allowance = int(init["memory_allowance"]) + (cars - 1) * int(init.get("car_memory", 0))
        address_space = seal.current_address_space() + allowance
        namespaces = seal.enter_namespaces()
        seal.limit_resources(address_space)
        ring = (self.policy.socket_fd,) if isinstance(self.policy, served.ServedPolicy) else ()
        seal.install_seccomp(
            read_fds=(0, self.reward.replies, *ring),
            write_fds=(self.reply_fd, 2, self.reward.requests, *ring),
            children=(self.reward.pid,),
        )
        self.send({"type": "ready", "namespaces": namespaces, "address_space": address_space})
        while (request := read_frame(self.requests)) is not None:
            handler = getattr(self, f"op_{request.get('op')}", None)
            if handler is None:
                self.send({"type": "error", "kind": "protocol", "message": "unknown request"})
                continue
            try:
                handler(request)
            except WorldUnavailable as error:  # a car near a box where PyBullet is missing
                self.send(_unavailable(error))
            except SlotsFailed as error:  # the policy server's, never the racer's code's
                self.send({"type": "error", "kind": "policy", "message": str(error)}, log=True)
                os._exit(75)

    def _build_envs(self, settings: dict, cars: int, in_turn: bool = False) -> list:
        """An environment per car. Car ``k`` of ``cars`` starts its training episodes
        ``k / cars`` of the lap further on, then advances its start per episode as one car
        does: the cars of a worker share an iteration's episodes, and between them cover the
        lap as one car driving them all would, rather than all drive the same stretch.
        ``in_turn``: cars that each drive one of a set of episodes (a checkpoint's evaluation)
        start where one car driving the set in turn would start each, its ``n``-th episode
        ``n`` advances on: car ``k``'s ``j``-th episode is the ``(j - 1) * cars + k + 1``-th."""
        import gymnasium

        import simulator

        envs, first = [], float(settings.get("start", 0.0))
        for car in range(cars):
            placed = settings if cars == 1 else {**settings, "start": (first + car / cars) % 1.0}
            # No reward_fn: the fleet scores every car's step, all of a step's in one request
            # (RewardProcess.calls, each car's call its own copy of the function), and no
            # environment here is stepped with env.step.
            env = gymnasium.make(simulator.ENV_ID, **placed)
            if in_turn and cars > 1:  # the first reset with a seed is episode 0, unplaced
                config = env.unwrapped.config
                advance = config["start_advance"]
                env.unwrapped.start = (first + (car + 1 - cars) * advance) % 1.0
                config["start_advance"] = advance * cars
            envs.append(env)
        for env in envs:  # PyBullet, where boxes or bots need it, connected before sealing
            with contextlib.suppress(WorldUnavailable):  # said when a car comes near one
                env.unwrapped.connect_world()
        observation, _ = envs[0].reset(seed=0)
        for view in VIEWS:  # the spectator's textures and the JPEG codec, before sealing
            jpeg(view_image(envs[0].unwrapped, view, observation))
        return envs

    def _build_policy(self, settings: dict) -> None:
        """The policy the rollout acts with: its network, built and run once before sealing;
        or, where the machine's policy server serves it (``served``), its stand-in over the
        slots it was handed, and torch never loaded."""
        # Car k takes seed + k: the worker gives each of its children seeds of their own.
        seeds = [int(settings.get("seed", 0)) + car for car in range(len(self.envs))]
        observations = [env.reset(seed=seed)[0] for env, seed in zip(self.envs, seeds, strict=True)]
        if settings.get("served"):
            self.policy = served.ServedPolicy(settings["algorithm"], settings["served"])
        else:
            import torch

            from rl.policies import Policy

            torch.set_num_threads(1)
            self.policy = Policy.build(
                settings["algorithm"],
                settings["architecture"],
                self.env.observation_space,
                self.env.action_space,
            )
            self.policy.explore(observations, [None] * len(observations))
        self.ppo = self.policy.ppo
        # One round trip to the reward process a step for all the cars (RewardProcess.calls).
        self.fleet = episode.Fleet(self.envs, self.policy, seeds, score=self.reward.calls)
        self.version = -1

    # Requests

    def op_weights(self, request: dict) -> None:
        self.policy.load_published(request["data"])
        self.version = int(request["version"])
        self.send({"type": "weights", "version": self.version})

    def op_episode(self, request: dict) -> None:
        """The next episode to end (``rl.episode.Fleet``): first ``start`` of the idle cars
        begin one in ``mode``, "explore" (the policy, sampling), "random" (uniform actions) or
        "evaluate" (the policy, deterministic: only a summary comes back); then the cars that
        drive step together until one's episode ends. The answer names that car and how many
        still drive; where several ended on one step, the next requests take the others first
        (the cars idle are started all the same, so the worker can check the count). Between
        steps, live frames (the lowest-numbered driving car's) and progress go out."""
        mode = request.get("mode", "explore")
        start = request.get("start", 1)
        if mode not in episode.MODES or not isinstance(start, int) or isinstance(start, bool):
            self.send({"type": "error", "kind": "protocol", "message": "unknown episode request"})
            return
        self.worker = int(request.get("worker", 0))
        fleet = self.fleet
        waiting = {car.index for car in self.finished}  # ended, their episodes not yet sent
        for car in [car for car in fleet.idle() if car.index not in waiting][: max(start, 0)]:
            fleet.start(car, mode, record=mode != "evaluate")
            self.episodes += 1
            self.episode_of[car.index] = self.episodes
        if not self.finished:
            if not fleet.driving():
                self.send({"type": "error", "kind": "protocol", "message": "no car is driving"})
                return
            reported = [time.perf_counter()]

            def stepped(car: episode.Car, observation: dict, info: dict, done: bool) -> None:
                self.driven += 1
                shown = car is next(other for other in fleet.cars if other.mode is not None)
                if shown:
                    self.env, self.observation = car.env, observation
                    self.shown_episode = self.episode_of.get(car.index, 0)
                self._live(observation if shown and not done else None)
                if time.perf_counter() - reported[0] >= PROGRESS_EVERY:
                    self.send({"type": "progress", "steps": self.driven}, log=True)
                    reported[0] = time.perf_counter()

            try:
                while not (ended := fleet.step(stepped)):
                    pass
            except (RewardFailure, RewardError) as error:
                if fleet.stepping is None:  # no car's call failed (sending the waypoints)
                    self.send(_failure(error), log=True)
                    return
                env, car = fleet.stepping.env.unwrapped, fleet.stepping.index
                which = {"car": car} if len(fleet.cars) > 1 else {}
                self.send(_failure(error, step=env.steps, status=env.status, **which), log=True)
                return
            self.finished.extend(ended)
        self._send_episode(self.finished.popleft(), len(fleet.driving()) + len(self.finished))

    def _send_episode(self, car: episode.Car, driving: int) -> None:
        """``car``'s episode as it ended: its summary and, unless it evaluated, its experience
        (``payload``), with ``car`` and how many cars still ``driving`` (theirs not yet sent
        counted)."""
        driven = car.driven
        summary = self._summary(car, driven.rewards, driven.info, driven.terminated)
        answer = {"type": "episode", "summary": summary, "car": car.index, "driving": driving}
        if not car.record:
            self.send(answer, log=True)
            return
        final_value = 0.0
        if self.ppo and driven.mode != "random" and not driven.terminated:
            final_value = self.policy.value(driven.last_observation)
        arrays = episode.experience(driven, hasattr(car.env.action_space, "n"), self.ppo)
        answer["payload"] = msgpack.packb(
            {
                **summary,
                "final_value": final_value,
                "arrays": encode_arrays(arrays),
                "trace": driven.trace,
            },
            use_bin_type=True,
        )
        self.send(answer, log=True)

    def _summary(self, car: episode.Car, rewards: list, info: dict, terminated: bool) -> dict:
        """What the trainer and the job's page read of an episode without its experience."""
        return {
            "worker": self.worker,
            "car": car.index,
            "version": self.version,
            "steps": len(rewards),
            "reward": float(sum(rewards)),
            "progress": info["progress"],
            "status": info["status"],
            "terminated": bool(terminated),
            "lap_time": car.env.unwrapped.sim_time if info["status"] == "lap_complete" else None,
        }

    def op_watch(self, request: dict) -> None:
        """Which views to send while driving; no answer."""
        self.views = {view for view in request.get("views", []) if view in VIEWS}

    def _live(self, observation: dict | None) -> None:
        """Between two steps: take a watch request that came, and send each watched view at
        15 frames/s (wall clock) of ``observation`` (the shown car's; None: none to show)."""
        now = time.perf_counter()
        if now - self._last_look >= LOOK_EVERY:
            self._last_look = now
            while self._requests_ready.poll(0):
                request = read_frame(self.requests)
                if request is None:  # the worker is gone
                    os._exit(0)
                if request.get("op") == "watch":
                    self.op_watch(request)
                elif request.get("op") == "exit":  # the worker stops mid-episode
                    os._exit(0)
        if observation is None or not self.views or now - self._last_frame < FRAME_INTERVAL:
            return
        self._last_frame = now
        for view in sorted(self.views):
            self._send_view(view, observation)

    def op_show(self, request: dict) -> None:
        """Send ``views`` once, as the car stands now (between episodes, while the trainer
        learns, a viewer who picks another view gets it at once), then ``shown``."""
        if self.env is not None:
            for view in sorted(set(request.get("views", [])) & set(VIEWS)):
                self._send_view(view, self.observation)
        self.send({"type": "shown"})

    def _send_view(self, view: str, observation: dict | None) -> None:
        env = self.env.unwrapped
        self.send(
            {
                "type": "frame",
                "view": view,
                "rendered_at": time.time(),
                "jpeg": jpeg(view_image(env, view, observation)),
                "worker": self.worker,
                "episode": self.shown_episode,
                "step": env.steps,
                "status": env.status,
                "progress": env.progress,
            }
        )

    def op_load(self, request: dict) -> None:
        try:
            self.reward.load(request["source"], copies=max(len(self.envs), 1))
        except RewardFailure as error:
            self.send(_failure(error), log=True)
        else:
            self.send({"type": "loaded"}, log=True)

    def op_samples(self, request: dict) -> None:
        self.send({"type": "samples", "samples": self.samples})

    def op_call(self, request: dict) -> None:
        try:
            reward = self.reward.call(request["params"])
        except (RewardFailure, RewardError) as error:
            self.send(_failure(error), log=True)
        else:
            self.send({"type": "reward", "value": reward}, log=True)

    def op_rescore(self, request: dict) -> None:
        """The reward for each of ``params`` (recorded steps, replayed), each given
        ``waypoints``; the first failure names its place in the list as its step."""
        waypoints = request["waypoints"]
        values = []
        for index, params in enumerate(request["params"]):
            try:
                values.append(self.reward.call({**params, "waypoints": waypoints}))
            except (RewardFailure, RewardError) as error:
                self.send(_failure(error, step=index), log=True)
                return
        self.send({"type": "rewards", "values": values}, log=True)

    def op_probe(self, request: dict) -> None:
        """What sealed code managed of the forbidden things: the racer's code in the reward
        process, and this process's own seals."""
        try:
            escaped = self.reward.probe(request)
        except RewardFailure as error:
            escaped = [f"stop the probe ({error})"]
        escaped += seal.escapes(
            {
                "read a file (from the child)": lambda: open(request["secret_path"]).read(),  # noqa: SIM115
                "start a process (from the child)": lambda: os.fork() == 0 and os._exit(0),
            }
        )
        self.send({"type": "probe", "escaped": escaped})

    def op_exit(self, request: dict) -> None:
        os._exit(0)


def _situations(settings: dict) -> list[dict]:
    """The reward function's sample situations on ``settings``' track, made in the child so that
    the web processes that validate reward functions never build a simulator."""
    from simulator.samples import situations

    found = situations(settings["track"], settings["direction"])
    return [{"name": s.name, "description": s.description, "params": s.params} for s in found]


def _unavailable(error: WorldUnavailable) -> dict[str, Any]:
    """The error frame for a simulator that needs PyBullet where it is missing: the worker's
    failure (``kind`` "simulation"), not the racer's code's."""
    return {"type": "error", "kind": "simulation", "message": str(error)[:500]}


def _failure(error: RewardFailure | RewardError, **where: Any) -> dict[str, Any]:
    """The error frame for a reward call that failed, with the step and status where it did."""
    if isinstance(error, RewardError):  # a value the reward process sent, refused here
        return {
            "type": "error",
            "kind": "value",
            "message": str(error)[:500],
            "line": None,
            **where,
        }
    return {**error.error, **where}


def main() -> None:
    # Die with the worker: a worker killed outright must leave no child behind.
    seal.die_with(os.getppid())
    try:
        Child().run()
    except BaseException:  # the child's own failure: say it on stderr, then go
        traceback.print_exc(file=sys.stderr)
        os._exit(70)
    os._exit(0)


if __name__ == "__main__":
    main()
