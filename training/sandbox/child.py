"""The sandbox child: ``python -s -m training.sandbox.child``, started by ``Sandbox``.

It reads requests on standard input and answers on standard output, in protocol frames. It first
loads everything user code may use (the allowed libraries, and the simulator when it is to drive
a rollout), then seals itself (``seal.py``), and only then receives the racer's code. What the
code prints becomes log messages; what it raises, returns or takes too long over becomes an error
message naming the line. This module never imports Django.
"""

from __future__ import annotations

import importlib
import io
import linecache
import os
import select
import signal
import sys
import time
import traceback
from typing import Any

import msgpack
import numpy as np

from simulator.controller import RolloutStats, drive
from simulator.rewards import RewardError, checked_reward
from simulator.spectator import FRAME_INTERVAL, VIEWS, jpeg, view_image
from training.experience import encode_arrays
from training.sandbox import seal
from training.sandbox.protocol import pack, read_frame

FILENAME = "<reward_function>"
PRELOADED = (
    "math", "random", "numpy", "scipy", "scipy.spatial", "scipy.interpolate", "scipy.signal",
    "scipy.stats", "scipy.optimize", "scipy.linalg", "scipy.special", "shapely",
    "shapely.geometry", "shapely.ops", "shapely.affinity",
)  # fmt: skip
PROGRESS_EVERY = 0.25  # [s] between progress messages during a rollout
LOOK_EVERY = 0.05  # [s] between looks for a watch request during an episode
MAX_LOG = 200  # characters per printed line kept, and lines kept between two messages


class CallTimeout(BaseException):
    """A call ran past its time limit; a BaseException, which ``except Exception`` lets by."""


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
        self.reward_function = None
        self.env = None
        self.policy = None
        self.ppo = True
        self.call_timeout = 1.0
        self.logs: list[str] = []
        self.printed = _Printed(self.logs)
        sys.stdout = self.printed
        signal.signal(signal.SIGALRM, _alarm)

    def send(self, message: dict[str, Any]) -> None:
        if "log" in message and self.printed.dropped:  # lines printed past what is kept
            message["log_dropped"], self.printed.dropped = self.printed.dropped, 0
        data = pack(message)
        while data:
            data = data[os.write(self.reply_fd, data) :]

    def run(self) -> None:
        init = read_frame(self.requests)
        if init is None:
            return
        self.call_timeout = float(init.get("call_timeout", 1.0))
        for name in PRELOADED:
            importlib.import_module(name)
        if init.get("env") is not None:
            self.env = self._build_env(init["env"])
        if init.get("policy") is not None:
            self._build_policy(init["policy"])
        address_space = seal.current_address_space() + int(init["memory_allowance"])
        namespaces = seal.enter_namespaces()
        seal.limit_resources(address_space)
        seal.install_seccomp(read_fd=0, write_fds=(self.reply_fd, 2))
        self.send({"type": "ready", "namespaces": namespaces, "address_space": address_space})
        while (request := read_frame(self.requests)) is not None:
            handler = getattr(self, f"op_{request.get('op')}", None)
            if handler is None:
                self.send({"type": "error", "kind": "protocol", "message": "unknown request"})
                continue
            handler(request)

    def _build_env(self, settings: dict):
        import cv2
        import gymnasium

        import simulator

        cv2.setNumThreads(0)  # no worker threads: the sealed process cannot start any
        env = gymnasium.make(simulator.ENV_ID, reward_fn=self._call_reward, **settings)
        observation, _ = env.reset(seed=0)
        for view in VIEWS:  # the spectator's textures and the JPEG codec, before sealing
            jpeg(view_image(env.unwrapped, view, observation))
        return env

    def _build_policy(self, settings: dict) -> None:
        """The policy network the rollout acts with, built and run once before sealing."""
        import torch

        from training.policies import Policy

        torch.set_num_threads(1)
        self.policy = Policy.build(
            settings["algorithm"], settings["architecture"],
            self.env.observation_space, self.env.action_space,
        )  # fmt: skip
        self.ppo = self.policy.ppo
        observation, _ = self.env.reset(seed=int(settings.get("seed", 0)))
        self.policy.act(observation, deterministic=False)
        self.version = -1

    # Requests

    def op_weights(self, request: dict) -> None:
        self.policy.load_published(request["data"])
        self.version = int(request["version"])
        self.send({"type": "weights", "version": self.version})

    def op_episode(self, request: dict) -> None:
        """One episode: ``mode`` "explore" (the policy, sampling), "random" (uniform actions) or
        "evaluate" (the policy, deterministic: only a summary comes back)."""
        env, mode = self.env, request.get("mode", "explore")
        self.worker = int(request.get("worker", 0))
        discrete = hasattr(env.action_space, "n")
        observation, info = env.reset()
        observations = {name: [value] for name, value in observation.items()}
        actions, rewards, values, log_probs, trace = [], [], [], [], []
        if mode != "evaluate":
            trace.append(list(info["trace"]))  # the prepare row, step 1, as DeepRacer's trace
        last_report = time.perf_counter()
        try:
            while True:
                if mode == "random":
                    action, value, log_prob = env.action_space.sample(), 0.0, 0.0
                else:
                    action, value, log_prob = self.policy.act(observation, mode == "evaluate")
                observation, reward, terminated, truncated, info = env.step(
                    self.policy.command(action, discrete)
                )
                actions.append(action)
                rewards.append(reward)
                values.append(value or 0.0)
                log_probs.append(log_prob or 0.0)
                if mode != "evaluate":
                    for name, value_now in observation.items():
                        observations[name].append(value_now)
                    trace.append(list(info["trace"]))
                self.observation = observation
                if terminated or truncated:
                    break
                self._live(observation)
                if time.perf_counter() - last_report >= PROGRESS_EVERY:
                    self.send({"type": "progress", "steps": len(rewards), "log": self._take_logs()})
                    last_report = time.perf_counter()
        except BaseException as error:  # user code may raise anything
            where = {"step": env.unwrapped.steps, "status": env.unwrapped.status}
            if isinstance(error, RewardError):
                self.send(_error("value", str(error), None, **where))
            else:
                self.send(_exception("exception", error, self.call_timeout, **where))
            return
        summary = {
            "worker": int(request.get("worker", 0)), "version": self.version,
            "steps": len(rewards), "reward": float(sum(rewards)), "progress": info["progress"],
            "status": info["status"], "terminated": bool(terminated),
            "lap_time": env.unwrapped.sim_time if info["status"] == "lap_complete" else None,
        }  # fmt: skip
        if mode == "evaluate":
            self.send({"type": "episode", "summary": summary, "log": self._take_logs()})
            return
        final_value = 0.0
        if self.ppo and mode != "random" and not terminated:
            final_value = self.policy.act(observation, deterministic=True)[1]
        arrays = {f"obs:{name}": np.stack(frames) for name, frames in observations.items()}
        if discrete:
            arrays["actions"] = np.array(actions, dtype=np.int64)
        else:
            arrays["actions"] = np.array(actions, dtype=np.float32).reshape(len(actions), -1)
        arrays["rewards"] = np.array(rewards, dtype=np.float32)
        if self.ppo:
            arrays["values"] = np.array(values, dtype=np.float32)
            arrays["log_probs"] = np.array(log_probs, dtype=np.float32)
        payload = msgpack.packb(
            {**summary, "final_value": final_value, "arrays": encode_arrays(arrays),
             "trace": trace}, use_bin_type=True,
        )  # fmt: skip
        self.send({"type": "episode", "summary": summary, "payload": payload,
                   "log": self._take_logs()})  # fmt: skip

    def op_watch(self, request: dict) -> None:
        """Which views to send while driving; no answer."""
        self.views = {view for view in request.get("views", []) if view in VIEWS}

    def _live(self, observation: dict) -> None:
        """Between two steps: take a watch request that came, and send each watched view at
        15 frames/s (wall clock)."""
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
        if not self.views or now - self._last_frame < FRAME_INTERVAL:
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
        self.send({
            "type": "frame", "view": view, "rendered_at": time.time(),
            "jpeg": jpeg(view_image(env, view, observation)),
            "worker": self.worker, "episode": env._episode,
            "step": env.steps, "status": env.status, "progress": env.progress,
        })  # fmt: skip

    def op_load(self, request: dict) -> None:
        source = request["source"]
        linecache.cache[FILENAME] = (len(source), None, source.splitlines(True), FILENAME)
        namespace = {"__name__": "reward_function_module", "__builtins__": __builtins__}
        try:
            code = compile(source, FILENAME, "exec")
        except SyntaxError as error:
            self.send(_error("syntax", f"{error.msg}", error.lineno))
            return
        try:
            self._limited(exec, code, namespace)
        except BaseException as error:  # whatever the module did is reported
            kind = "import" if isinstance(error, ImportError) else "exception"
            self.send(_exception(kind, error, self.call_timeout))
            return
        function = namespace.get("reward_function")
        if not callable(function):
            self.send(_error("definition", "The code must define reward_function(params).", None))
            return
        self.reward_function = function
        self.send({"type": "loaded"})

    def op_call(self, request: dict) -> None:
        params = _params(request["params"])
        try:
            reward = self._call_reward(params)
        except RewardError as error:
            self.send(_error("value", str(error), None))
        except BaseException as error:  # user code may raise anything
            self.send(_exception("exception", error, self.call_timeout))
        else:
            self.send({"type": "reward", "value": reward, "log": self._take_logs()})

    def op_rollout(self, request: dict) -> None:
        """Drive ``steps`` steps of the environment with the reward function, reporting progress."""

        def report(stats: RolloutStats) -> None:
            self.send({"type": "progress", "steps": stats.steps, "log": self._take_logs()})

        started = time.perf_counter()
        try:
            stats = drive(
                self.env,
                int(request["steps"]),
                random_actions=request.get("driver") == "random",
                seed=int(request.get("seed", 0)),
                report=report,
            )
        except BaseException as error:  # user code may raise anything
            where = {"step": self.env.unwrapped.steps, "status": self.env.unwrapped.status}
            if isinstance(error, RewardError):
                self.send(_error("value", str(error), None, **where))
            else:
                self.send(_exception("exception", error, self.call_timeout, **where))
            return
        self.send({
            "type": "rollout", "steps": stats.steps, "episodes": stats.episodes,
            "reward": stats.reward, "statuses": dict(stats.statuses),
            "elapsed": time.perf_counter() - started, "log": self._take_logs(),
        })  # fmt: skip

    def op_probe(self, request: dict) -> None:
        """Try what sealed code must not be able to do; report what got through."""
        escaped = []
        attempts = {
            "read a file": lambda: open(request["secret_path"]).read(),  # noqa: SIM115
            "connect to the network": lambda: __import__("socket").create_connection(
                ("127.0.0.1", int(request["port"])), timeout=1
            ),
            "start a process": lambda: os.fork() == 0 and os._exit(0),
            "run a program": lambda: os.execv("/bin/true", ["true"]),  # noqa: S606
            "write a file": lambda: open("/tmp/pitlane-sandbox-probe", "w").write("x"),  # noqa: S108, SIM115
        }
        for name, attempt in attempts.items():
            try:
                attempt()
            except OSError:
                continue
            escaped.append(name)
        self.send({"type": "probe", "escaped": escaped})

    def op_exit(self, request: dict) -> None:
        os._exit(0)

    # Calling user code

    def _call_reward(self, params: dict) -> float:
        return checked_reward(self._limited(self.reward_function, params))

    def _limited(self, function, *args):
        """``function(*args)`` within the per-call time limit."""
        signal.setitimer(signal.ITIMER_REAL, self.call_timeout)
        try:
            return function(*args)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)

    def _take_logs(self) -> list[str]:
        logs, self.logs[:] = self.logs[:MAX_LOG], []
        return logs


class _Printed(io.TextIOBase):
    """Standard output for user code: each printed line becomes a log message. At most
    ``MAX_LOG`` lines of ``MAX_LOG`` characters wait to be sent; lines past them are counted
    (``dropped``), not kept, so that a print flood costs neither memory nor the pipe."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines
        self.partial = ""
        self.dropped = 0

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        room = max(MAX_LOG - len(self.lines), 0)
        *complete, rest = (self.partial + str(text)).split("\n", room)
        if len(complete) == room and "\n" in rest:  # no room for the lines in ``rest``
            self.dropped += rest.count("\n")
            rest = rest[rest.rindex("\n") + 1 :]
        self.lines.extend(line[:MAX_LOG] for line in complete)
        self.partial = rest[:MAX_LOG]
        return len(text)


def _alarm(signum, frame) -> None:
    raise CallTimeout


def _params(params: dict) -> dict:
    """Params as the simulator makes them: waypoints and locations as tuples."""
    for key in ("waypoints", "objects_location"):
        if key in params:
            params[key] = [tuple(point) for point in params[key]]
    return params


def _error(kind: str, message: str, line: int | None, **where: Any) -> dict[str, Any]:
    return {"type": "error", "kind": kind, "message": message[:500], "line": line, **where}


def _exception(kind: str, error: BaseException, timeout: float, **where: Any) -> dict[str, Any]:
    """An error message for what user code raised, with the line in the racer's code."""
    line = None
    for frame in traceback.extract_tb(error.__traceback__):
        if frame.filename == FILENAME:
            line = frame.lineno
    if isinstance(error, CallTimeout):
        return _error("timeout", f"The reward function took longer than {timeout:g} s.", line,
                      **where)  # fmt: skip
    if isinstance(error, MemoryError):
        return _error("memory", "The reward function ran out of memory.", line, **where)
    if isinstance(error, SystemExit):
        return _error(kind, "The reward function called exit(); it must return a reward.", line,
                      **where)  # fmt: skip
    try:
        text = f"{type(error).__name__}: {error}"
    except BaseException:  # a message that cannot be printed is still an error
        text = type(error).__name__
    return _error(kind, text, line, **where)


def main() -> None:
    try:
        Child().run()
    except BaseException:  # the child's own failure: say it on stderr, then go
        traceback.print_exc(file=sys.stderr)
        os._exit(70)
    os._exit(0)


if __name__ == "__main__":
    main()
