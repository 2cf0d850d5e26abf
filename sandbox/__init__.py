"""Running racers' code: a sandbox child per use, and the worker's self-test of the sandbox.

``Sandbox`` has ``sandbox.child`` forked by the worker process's zygote (``zygote.py``), a clean
interpreter (fork and exec, never a fork of the worker) with an empty environment that has imported
the child's code once; the child gets only its three standard pipes. It waits until the child has
sealed itself, then sends it the racer's code and requests. The racer's code runs in a process of
its own beneath the child (``reward.py``), which times each call from outside and cannot be written
to the worker by it. Here, every request has a deadline from the moment it is sent (an episode: a
step at least every ``GRACE`` past its cars' calls' deadlines), every write to the child has one,
the frames read ahead and the standard error kept are bounded, and a child that breaks the protocol
is killed; so no reward function can hang, flood or take down a worker. The child dies with the
worker (its zygote ends when the worker does). Where the machine's policy server serves the child
its policy (``policy_lease``, ``served.py``), the child is handed its slots there and nothing else
of the server's, and loads no torch. This package imports no Django: the child imports it too.

Long because every bound above lives in the one client class, where a reader checks them all.
"""

from __future__ import annotations

import logging
import os
import queue
import signal
import socket
import subprocess
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from rl.policy_lease import PolicyLease, PolicyServerFailed
from sandbox import served
from sandbox.protocol import Late, ProtocolError, pack, read_frame, write_by
from sandbox.spawner import Zygote, ZygoteFailed
from simulator.rewards import RewardError, checked_reward

logger = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[1]
MiB = 1024 * 1024
GRACE = 2.0  # [s] past a call's own time limit before the child is killed
KILL_GRACE = 0.5  # [s] past a call's time limit (which the reward process enforces on itself,
# to name the line) before the child kills that process from outside
LOG_KEEP = 1000  # printed lines kept until taken; later ones are counted in ``logs_dropped``
FRAMES_AHEAD = 64  # frames read from the child and not yet taken; the reader waits beyond
STDERR_KEEP = 16 * 1024  # [bytes] the end of the child's standard error, kept for the log
WEIGHTS_TIMEOUT = 30.0  # [s] to send a policy's weights (up to about 55 MB) and hear back
CHILD_ENVIRONMENT = {
    # Nothing of the worker's: no secrets, no paths. Only one thread per numerical library.
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "PYTHONDONTWRITEBYTECODE": "1",
}


class SandboxFailure(Exception):
    """The racer's code failed, misbehaved or was stopped; says where, in a racer's words."""

    def __init__(
        self,
        kind: str,
        message: str,
        line: int | None = None,
        step: int | None = None,
        status: str | None = None,
        car: int | None = None,
    ) -> None:
        super().__init__(message)
        self.kind, self.message, self.line, self.step, self.status = (
            kind,
            message,
            line,
            step,
            status,
        )
        self.car = car  # which of the sandbox's cars was driving, where several do

    def __str__(self) -> str:
        where = []
        if self.step is not None:
            where.append(f"at step {self.step}" + (f" ({self.status})" if self.status else ""))
        if self.line is not None:
            where.append(f"line {self.line}")
        return (", ".join(where) + ": " if where else "") + self.message


def portable_env(env: dict | None) -> dict | None:
    """``env`` with a track the child could not find by name sent inline instead: the child has
    no database (nor, in a cluster, the disk a track was added on), so a track staff added
    travels as its route file's bytes and metadata (``simulator.tracks.inline``)."""
    if not env or not isinstance(env.get("track"), str):
        return env
    from simulator import tracks

    return {**env, "track": tracks.inline(env["track"])}


class SandboxUnavailable(Exception):
    """This machine cannot hold racers' code safely; the message says what got through."""


@dataclass
class Sandbox:
    """One sandbox child. ``env``: settings for a simulator the child builds before sealing,
    once per car of ``cars`` (``episode`` drives them together)."""

    env: dict | None = None
    cars: int = 1
    in_turn: bool = False  # the cars start where one car driving their episodes in turn would
    # (a checkpoint's evaluation: each drives one of its episodes), not k / cars of the lap apart
    policy: dict | None = None  # {"algorithm", "architecture", "seed", "job"}: a policy to act with
    policy_lease: PolicyLease | None = None  # the child's slots in the machine's policy server,
    # where it serves the policy (``sandbox.served``); None: the child holds it
    samples: dict | None = None  # {"track", "direction"}: sample situations, made before sealing
    call_timeout: float = 1.0  # [s] per call of the reward function
    memory_allowance: int = 512 * MiB  # [bytes] the child may map beyond what it has at sealing,
    # and the reward process beyond what it has at its own: the racer's code gets this whatever
    # the cars
    car_memory: int = 0  # [bytes] more the child (never the racer's code) may map per car past one
    start_timeout: float = 60.0  # [s]
    niceness: int = 0  # the child's and its reward process's, above this process's own: a job
    # with a smaller share of the machine drives behind the others (jobs.shares)
    logs: deque = field(default_factory=lambda: deque(maxlen=LOG_KEEP))
    logs_dropped: int = 0  # lines printed and not kept: past LOG_KEEP, or the child's bound
    report: dict = field(default_factory=dict)
    on_frame: Callable[[dict], None] | None = None  # given each frame the child sends (unchecked)

    def __post_init__(self) -> None:
        self._process: subprocess.Popen | None = None
        self._frames: queue.Queue = queue.Queue(maxsize=FRAMES_AHEAD)
        self._closed = threading.Event()
        self.stderr_tail = b""
        self.driving = 0  # cars with episodes under way, as the child last said

    def __enter__(self) -> Sandbox:
        try:
            self.start()
        except BaseException:  # the policy's slots, the child, its readers: none outlives it
            self.close()
            raise
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def start(self) -> dict:
        """Start the child and wait until it is sealed; what it reports of its seals. Where its
        policy is served, its slots are opened first and handed to it."""
        env, policy = portable_env(self.env), self.policy
        handed: tuple[int, ...] = ()
        if policy is not None and self.policy_lease is not None:
            try:
                self.policy_lease.open(
                    job=int(policy.get("job", 0)),
                    algorithm=policy["algorithm"],
                    architecture=policy["architecture"],
                    env=env,
                    seed=int(policy.get("seed", 0)),
                    cars=self.cars,
                )
            except PolicyServerFailed as error:
                raise SandboxFailure("policy", str(error)[:500]) from None
            policy = {**policy, "served": self.policy_lease.child_settings(served.CHILD_PATIENCE)}
            handed = self.policy_lease.fds
        # The child takes its niceness before it forks its reward process, which inherits it.
        niceness = min(os.getpriority(os.PRIO_PROCESS, 0) + self.niceness, 19)
        try:
            self._process = _zygote().spawn(pass_fds=handed, niceness=niceness)
        except ZygoteFailed as error:
            logger.error("No sandbox child could start: %s", error)
            raise SandboxFailure("crashed", "The simulation's process could not start.") from None
        if self.policy_lease is not None:
            self.policy_lease.handed()  # the server sees the child go when it goes
        os.set_blocking(self._process.stdin.fileno(), False)
        threading.Thread(target=self._read_frames, daemon=True).start()
        threading.Thread(target=self._read_stderr, daemon=True).start()
        self.report = self._request(
            {
                "call_timeout": self.call_timeout,
                "memory_allowance": self.memory_allowance,
                "car_memory": self.car_memory,
                "env": env,
                "cars": self.cars,
                "in_turn": self.in_turn,
                "policy": policy,
                "samples": portable_env(self.samples),
                "op": "start",
            },
            {"ready"},
            self.start_timeout,
        )
        return self.report

    def load(self, source: str) -> None:
        """Run the racer's module, once per car that drives (each copy's top level within the
        call's limit); ``SandboxFailure`` if it does not define a reward function."""
        copies = self.cars if self.env is not None else 1
        self._request({"op": "load", "source": source}, {"loaded"}, copies * self.call_timeout)

    def situations(self) -> list[dict]:
        """The sample situations of ``samples``' track (``simulator.samples``), as the child
        made them: each a dict of name, description and the reward params there."""
        reply = self._request({"op": "samples"}, {"samples"})
        samples = reply.get("samples")
        if not isinstance(samples, list) or not all(isinstance(s, dict) for s in samples):
            raise SandboxFailure("protocol", "The sandbox sent samples that are not a list.")
        return samples

    def call(self, params: dict, timeout: float | None = None) -> float:
        """The reward for ``params``, checked here: a finite number within ±1e5."""
        reply = self._request({"op": "call", "params": params}, {"reward"}, timeout)
        try:
            return checked_reward(reply.get("value"))
        except RewardError as error:
            raise SandboxFailure("value", str(error)) from None

    def rescore(self, waypoints: list, params: list[dict]) -> list[float]:
        """The reward for each of ``params`` (reward params without their ``waypoints``, which
        each is given): ``SandboxFailure`` at the first that fails, its ``step`` the failing
        one's index in ``params``. Each call is timed as ``call`` times one."""
        timeout = self.call_timeout * max(len(params), 1)
        reply = self._request(
            {"op": "rescore", "waypoints": waypoints, "params": params}, {"rewards"}, timeout
        )
        values = reply.get("values")
        if not isinstance(values, list) or len(values) != len(params):
            raise SandboxFailure("protocol", "The sandbox sent rewards that do not match.")
        try:
            return [checked_reward(value) for value in values]
        except RewardError as error:
            raise SandboxFailure("value", str(error)) from None

    def set_weights(self, version: int, data: bytes) -> None:
        """Act with the policy weights of ``version`` from now on: loaded where the policy is
        (here, where it is served), the child told the version its episodes are of."""
        if self.policy_lease is not None:
            try:
                self.policy_lease.weights(data)
            except PolicyServerFailed as error:
                raise SandboxFailure("policy", str(error)[:500]) from None
            data = b""
        self._request(
            {"op": "weights", "version": version, "data": data}, {"weights"}, WEIGHTS_TIMEOUT
        )

    def episode(
        self,
        mode: str = "explore",
        worker: int = 0,
        on_progress: Callable[[int], None] | None = None,
        *,
        start: int = 1,
    ) -> dict:
        """The next episode of the child's cars to end, ``start`` of its idle cars first
        beginning one in ``mode`` (with one car: drive one episode): ``summary`` (steps, reward,
        progress, status, lap_time), ``car`` (which), ``driving`` (how many cars have episodes
        under way, to come from the next requests) and, unless evaluating, ``payload``: the
        episode's experience, encoded for the experience buffer. ``start`` may be no more
        than the cars idle (``cars - driving``); the child starts them all, so each answer's
        ``driving`` must be the last answer's, plus ``start``, less the one sent."""
        request = {"op": "episode", "mode": mode, "worker": worker, "start": start}
        reply = self._request(request, {"episode"}, self._step_limit(), on_progress or _ignore)
        if not isinstance(reply.get("summary"), dict):
            self._kill()
            raise SandboxFailure("protocol", "The sandbox sent an episode without a summary.")
        if mode != "evaluate" and not isinstance(reply.get("payload"), bytes):
            self._kill()
            raise SandboxFailure("protocol", "The sandbox sent an episode without its experience.")
        car, driving = _int_or_none(reply.get("car")), _int_or_none(reply.get("driving"))
        if car is None or not 0 <= car < self.cars or driving != self.driving + start - 1:
            self._kill()
            raise SandboxFailure(
                "protocol", "The sandbox sent an episode of no car it drives, or lost count."
            )
        self.driving = driving
        return reply

    def watch(self, views: set[str]) -> None:
        """Have the child send these views (``"spectator"``, ``"camera"``) at 15 frames/s while
        it drives, to ``on_frame``; an empty set stops them. Takes effect within an episode."""
        self._send({"op": "watch", "views": sorted(views)}, time.monotonic() + GRACE)

    def show(self, views: set[str]) -> None:
        """Have the child send these views once, as its car stands now, to ``on_frame``: for a
        viewer while the child waits between episodes."""
        self._request({"op": "show", "views": sorted(views)}, {"shown"}, 5.0)

    def probe(self, secret_path: str, port: int) -> list[str]:
        """What the sealed child managed to do of the forbidden things; [] when it held."""
        reply = self._request(
            {"op": "probe", "secret_path": secret_path, "port": port}, {"probe"}, 30.0
        )
        return [str(item) for item in reply.get("escaped", [])]

    def close(self) -> None:
        if self.policy_lease is not None:
            self.policy_lease.close()
        process = self._process
        if process is None:
            return
        if process.poll() is None:
            try:
                self._send({"op": "exit"}, time.monotonic() + 1.0)
                process.wait(1.0)
            except (SandboxFailure, subprocess.TimeoutExpired):
                self._kill()
        self._closed.set()
        for stream in (process.stdin, process.stdout, process.stderr):
            if stream is not None:
                stream.close()
        self._process = None

    # Talking to the child

    def _request(
        self,
        message: dict,
        expected: set[str],
        timeout: float | None = None,
        on_progress: Callable[[int], None] | None = None,
    ) -> dict:
        """Send ``message`` and wait for its answer: by ``timeout`` (the call's limit where
        None) and ``GRACE`` from now, or, with ``on_progress`` (an episode, a rollout), with a
        step at least that often."""
        deadline = time.monotonic() + (timeout or self.call_timeout) + GRACE
        self._send(message, deadline)
        stall = self._step_limit() + GRACE if on_progress is not None else None
        return self._wait(expected, deadline, message["op"], on_progress, stall)

    def _step_limit(self) -> float:
        """[s] the most a step of all the cars may hold the child: the reward process is
        asked once for them all, and the child gives each car's call its own deadline, the
        call's limit and ``KILL_GRACE`` after the car before it answered; a child whose policy
        is served also waits up to ``served.CHILD_PATIENCE`` for the server's answer, then says
        so itself."""
        served_wait = served.CHILD_PATIENCE if self.policy_lease is not None else 0.0
        return self.cars * (self.call_timeout + KILL_GRACE) + served_wait

    def _send(self, message: dict, deadline: float) -> None:
        if self._process is None:
            raise SandboxFailure("stopped", "The sandbox is not running.")
        try:
            write_by(self._process.stdin.fileno(), pack(message), deadline)
        except Late:
            self._kill()
            raise SandboxFailure(
                "timeout", "The sandbox stopped taking requests; it was stopped."
            ) from None
        except OSError:
            raise self._died() from None

    def _wait(
        self,
        expected: set[str],
        deadline: float,
        what: str,
        on_progress: Callable[[int], None] | None = None,
        stall: float | None = None,
    ) -> dict:
        """The answer to ``what``, by ``deadline``; with ``stall``, a progress frame with more
        steps than the last moves the deadline to ``stall`` seconds after it."""
        steps = -1
        while True:
            try:
                frame = self._frames.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                self._kill()
                if what == "start":
                    raise SandboxFailure(
                        "timeout", f"The sandbox did not start in {self.start_timeout:g} s."
                    ) from None
                limit = f"{self.call_timeout:g} s"
                message = f"The reward function took longer than {limit}; it was stopped."
                raise SandboxFailure("timeout", message) from None
            if frame is None:
                raise self._died()
            if isinstance(frame, ProtocolError):
                self._kill()
                raise SandboxFailure("protocol", f"The sandbox sent something unreadable: {frame}")
            self._keep_logs(frame.get("log"), frame.get("log_dropped"))
            kind = frame.get("type")
            if kind == "progress" and stall is not None:
                now = frame.get("steps")
                if not isinstance(now, int) or isinstance(now, bool) or now <= steps:
                    self._kill()
                    raise SandboxFailure(
                        "protocol", "The sandbox reported progress it had not made."
                    )
                steps, deadline = now, time.monotonic() + stall
                on_progress(now)
                continue
            if kind == "frame" and (stall is not None or what == "show"):
                if self.on_frame is not None:
                    self.on_frame(frame)
                continue
            if kind in expected:
                return frame
            if kind == "error":
                raise _failure_of(frame)
            self._kill()
            raise SandboxFailure(
                "protocol", f"The sandbox answered {str(kind)[:20]!r} to {what!r}."
            )

    def take_logs(self) -> tuple[list[str], int]:
        """The printed lines kept since the last take, and how many more were not kept."""
        taken = (list(self.logs), self.logs_dropped)
        self.logs.clear()
        self.logs_dropped = 0
        return taken

    def _keep_logs(self, lines: Any, dropped: Any) -> None:
        lines = lines if isinstance(lines, list) else []
        room = max(LOG_KEEP - len(self.logs), 0)
        self.logs.extend(str(line)[:200] for line in lines[:room])
        self.logs_dropped += max(len(lines) - room, 0)
        if isinstance(dropped, int) and not isinstance(dropped, bool) and dropped > 0:
            self.logs_dropped += dropped

    def _died(self) -> SandboxFailure:
        process = self._process
        code = process.wait(5) if process is not None else None
        if self.stderr_tail:
            logger.warning(
                "A sandbox child stopped (%s); its last words: %s",
                code,
                self.stderr_tail[-2000:].decode("utf-8", "replace"),
            )
        # The child runs only our code (the racer's runs in its reward process, whose end the
        # child reports): its own end is the simulation's, not the reward function's.
        how = (
            f"was killed by {signal.Signals(-code).name}"
            if code and code < 0
            else (f"exited with status {code}")
        )
        return SandboxFailure("crashed", f"The simulation's process stopped: it {how}.")

    def _kill(self) -> None:
        if self._process is not None and self._process.poll() is None:
            self._process.kill()
            self._process.wait()

    def _read_frames(self) -> None:
        """Read the child's frames ahead into ``_frames``, at most ``FRAMES_AHEAD``; None at
        the end, or the ``ProtocolError`` that ended them."""
        stream = self._process.stdout
        try:
            while (frame := read_frame(stream)) is not None:
                if not self._put(frame):
                    return
        except ProtocolError as error:
            self._put(error)
            return
        except (OSError, ValueError):
            pass
        self._put(None)

    def _put(self, item: Any) -> bool:
        """Queue ``item`` once there is room; False if the sandbox was closed meanwhile."""
        while not self._closed.is_set():
            try:
                self._frames.put(item, timeout=0.5)
                return True
            except queue.Full:
                continue
        return False

    def _read_stderr(self) -> None:
        """Drain the child's standard error in fixed-size chunks, keeping its last
        ``STDERR_KEEP`` bytes: a flood without a newline costs nothing here."""
        fd = self._process.stderr.fileno()
        try:
            while chunk := os.read(fd, 65536):
                self.stderr_tail = (self.stderr_tail + chunk)[-STDERR_KEEP:]
        except OSError:
            pass


@cache
def _zygote() -> Zygote:
    """This process's zygote, which forks its sandbox children (``sandbox.zygote``)."""
    return Zygote(CHILD_ENVIRONMENT)


def _failure_of(frame: dict) -> SandboxFailure:
    """The failure an error frame of the child's tells, its parts bounded."""
    return SandboxFailure(
        str(frame.get("kind", "error"))[:20],
        str(frame.get("message", ""))[:500],
        _int_or_none(frame.get("line")),
        _int_or_none(frame.get("step")),
        str(frame["status"])[:20] if frame.get("status") else None,
        _int_or_none(frame.get("car")),
    )


def _ignore(steps: int) -> None:
    """Progress nobody follows; it still proves the child is driving."""


def _int_or_none(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


@dataclass(frozen=True)
class SelfTest:
    ok: bool
    escaped: tuple[str, ...]
    namespaces: bool
    detail: str


def self_test() -> SelfTest:
    """Start a sealed child and have it try to read a secret file, connect to a listening socket,
    fork, exec and write a file: all must fail."""
    with tempfile.TemporaryDirectory(prefix="pitlane-sandbox-test-") as directory:
        secret = Path(directory) / "secret"
        secret.write_text("do not read me")
        secret.chmod(0o600)
        with socket.socket() as listener:
            listener.bind(("127.0.0.1", 0))
            listener.listen()
            try:
                with Sandbox(start_timeout=120) as sandbox:
                    escaped = sandbox.probe(str(secret), listener.getsockname()[1])
                    namespaces = bool(sandbox.report.get("namespaces"))
            except (SandboxFailure, OSError) as error:
                return SelfTest(False, (), False, f"the sandbox could not start: {error}")
    if escaped:
        detail = "sealed code could " + ", ".join(escaped)
    else:
        detail = "held: files, network, processes and writes are refused" + (
            "; in its own user and network namespaces"
            if namespaces
            else "; namespaces are not available here, seccomp alone holds"
        )
    return SelfTest(not escaped, tuple(escaped), namespaces, detail)


@cache
def verified() -> SelfTest:
    """This process's self-test, run once; ``SandboxUnavailable`` if the sandbox does not hold."""
    result = self_test()
    if not result.ok:
        raise SandboxUnavailable(f"Racers' code cannot run on this machine: {result.detail}.")
    return result
