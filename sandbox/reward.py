"""The racer's code in a process of its own: the reward process, forked by the sandbox child.

The child (``child.py``) runs only our code: the simulator, the policy and the protocol with the
worker. It forks this process before it builds either, and the racer's module runs here alone,
sealed more tightly than the child: it can read its request pipe, write its reply pipe and
standard error, and nothing else. So whatever the racer's code writes, it cannot speak to the
worker; and every call is timed by the child, from outside: a reply not whole by the call's
deadline (an alarm ignored, a frame begun and never finished) gets this process killed, and the
call fails with the reason. The child checks every reward it is sent (``checked_reward``): what
this process says is never trusted.

Messages are protocol frames: ``{"op": "load", "source"}``, ``{"op": "call", "params", "car"}``,
``{"op": "calls", "calls": [[car, params], ...]}`` (a step of all a rollout's cars in one
request, answered one frame a call as each ends: ``{"type": "reward", "value", "car"}``, or the
error of the first call that failed, naming its ``car``, after which no more are called), the
waypoints only when they change (``{"op": "waypoints", "waypoints"}`` first) and
``{"op": "probe", ...}``; each frame carries ``log`` (the lines printed meanwhile). The child
reads each of a step's frames by its call's own deadline, from the frame before it: so the bound
on every call, and the car it names, are a single call's, whatever the cars.

Long because it is both ends of one protocol, the child's handle and the reward process's
host, kept side by side so that each request is read beside its answer.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import linecache
import os
import resource
import signal
import sys
import time
import traceback
from typing import Any

from sandbox import CHILD_ENVIRONMENT, KILL_GRACE, _int_or_none, seal
from sandbox.protocol import Late, ProtocolError, pack, read_frame, read_frame_by, write_by
from simulator.rewards import RewardError, checked_reward

FILENAME = "<reward_function>"
PRELOADED = (
    "math",
    "random",
    "numpy",
    "scipy",
    "scipy.spatial",
    "scipy.interpolate",
    "scipy.signal",
    "scipy.stats",
    "scipy.optimize",
    "scipy.linalg",
    "scipy.special",
    "shapely",
    "shapely.geometry",
    "shapely.ops",
    "shapely.affinity",
    "encodings.idna",  # so that code reaching for the network meets the seal, not a missing codec
)
MAX_LOG = 200  # characters per printed line kept, and lines kept between two messages
MAX_REPLY = 1024 * 1024  # [bytes] the largest reply frame: a reward and 200 printed lines
KINDS = {"syntax", "import", "exception", "definition", "value", "timeout", "memory"}
OUT_OF_TURN = "The reward function's process answered for a car other than the one asked about."


class CallTimeout(BaseException):
    """A call ran past its time limit; a BaseException, which ``except Exception`` lets by."""


class RewardFailure(Exception):
    """The racer's code failed, or its process misbehaved; ``error`` is the error frame
    (``kind``, ``message``, ``line``) for the worker, ``car`` the car whose call failed (None
    where no car's call was under way: loading the code, a process already stopped)."""

    def __init__(
        self, kind: str, message: str, line: int | None = None, car: int | None = None
    ) -> None:
        super().__init__(message)
        self.error = _error(kind, message, line)
        self.car = car


# The child's side


class Printed:
    """Lines the reward process printed, waiting for the next message to the worker: at most
    ``MAX_LOG`` of ``MAX_LOG`` characters; the rest are counted in ``dropped``."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.dropped = 0

    def add(self, lines: Any, dropped: Any) -> None:
        lines = lines if isinstance(lines, list) else []
        room = max(MAX_LOG - len(self.lines), 0)
        self.lines.extend(str(line)[:MAX_LOG] for line in lines[:room])
        self.dropped += max(len(lines) - room, 0)
        if isinstance(dropped, int) and not isinstance(dropped, bool) and dropped > 0:
            self.dropped += min(dropped, 1 << 40)

    def take(self) -> tuple[list[str], int]:
        taken = (self.lines, self.dropped)
        self.lines, self.dropped = [], 0
        return taken


class RewardProcess:
    """The child's handle on the reward process: start it, load the racer's code, call it."""

    def __init__(self, call_timeout: float, memory_allowance: int) -> None:
        self.call_timeout = call_timeout
        self.printed = Printed()
        self.round_trips = 0  # requests answered or failed: one a step for all a rollout's cars
        self._waypoints: list | None = None
        parent = os.getpid()
        request_read, self.requests = os.pipe()
        self.replies, reply_write = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the reward process
            try:
                os.close(self.requests)
                os.close(self.replies)
                _serve(parent, request_read, reply_write, call_timeout, memory_allowance)
            except BaseException:  # its own failure (the racer's are answered): say it, then go
                traceback.print_exc(file=sys.stderr)
            finally:
                os._exit(70)
        os.close(request_read)
        os.close(reply_write)
        os.set_blocking(self.requests, False)
        os.set_blocking(self.replies, False)

    def wait_ready(self, limit: float) -> None:
        """Wait until the process has sealed itself (it imports the allowed libraries first,
        while the child builds the simulator)."""
        self._ask({"op": "hello"}, "ready", limit)

    def load(self, source: str, copies: int = 1) -> None:
        """Run the racer's module ``copies`` times, each in a namespace of its own: one per car
        that calls it, so that a function keeping values in globals between calls (as
        DeepRacer's, called by one car in order, may) sees only its own car's calls."""
        limit = copies * self.call_timeout + KILL_GRACE
        self._ask({"op": "load", "source": source, "copies": copies}, "loaded", limit)

    def call(self, params: dict, car: int = 0) -> float:
        """The reward for ``params`` from car ``car``'s copy of the function, checked here
        (``RewardError`` if it is not one)."""
        params = self._sent([params])[0]
        reply = self._ask(
            {"op": "call", "params": params, "car": car},
            "reward",
            self.call_timeout + KILL_GRACE,
            car,
        )
        return checked_reward(reply.get("value"))

    def calls(self, calls: list[tuple[int, dict]]) -> list[float]:
        """The rewards for a step of several cars, ``calls`` of (car, params), asked in one
        request. The reward process answers each call as it ends, a frame a car (its reward or
        its error), and each frame is due by the call's own deadline, ``call_timeout`` and
        ``KILL_GRACE`` after the frame before it (after the request, for the first): each call
        is held to ``call``'s bound, from outside, however many cars. The first call that fails
        ends the step with ``RewardFailure`` naming its ``car``, whatever the reason (a process
        killed past that call's deadline, or crashed, included); the cars after it are not
        called, and those before it are not given their rewards: any car's failure fails the
        job."""
        if not calls:
            return []
        cars = [car for car, _ in calls]
        sent = zip(cars, self._sent([params for _, params in calls]), strict=True)
        request = {"op": "calls", "calls": [[car, params] for car, params in sent]}
        limit = self.call_timeout + KILL_GRACE
        deadline = self._send(request, limit, cars[0])
        rewards = []
        for car in cars:
            try:
                reply = self._answer("reward", deadline, car)
            except RewardFailure as failure:
                if failure.car == car:
                    raise
                reply = {"car": failure.car}  # an error frame for another car: out of turn
            if reply.get("car") != car or isinstance(reply.get("car"), bool):
                self.stop()
                raise RewardFailure("protocol", OUT_OF_TURN, None, car)
            try:
                rewards.append(checked_reward(reply.get("value")))
            except RewardError as error:  # a value it was never given: refused here
                raise RewardFailure("value", str(error), None, car) from None
            deadline = time.monotonic() + limit
        return rewards

    def _sent(self, params: list[dict]) -> list[dict]:
        """Each of ``params`` as sent, its waypoints apart: sent first (once) where they
        changed. The params of one batch share their waypoints (a rollout's cars one track)."""
        waypoints = params[0].get("waypoints")
        if any(each.get("waypoints") != waypoints for each in params[1:]):
            raise ValueError("The cars of one call of the reward function drive one track.")
        if waypoints is not None and waypoints != self._waypoints:
            self._ask({"op": "waypoints", "waypoints": waypoints}, "waypoints", 5.0)
            self._waypoints = waypoints
        return [
            {name: value for name, value in each.items() if name != "waypoints"} for each in params
        ]

    def probe(self, request: dict) -> list[str]:
        reply = self._ask({**request, "op": "probe"}, "probe", 30.0)
        escaped = reply.get("escaped")
        return [str(item)[:100] for item in escaped[:10]] if isinstance(escaped, list) else []

    def stop(self) -> None:
        if self.pid is None:
            return
        with contextlib.suppress(OSError):
            os.kill(self.pid, signal.SIGKILL)
        self._reap()

    def _ask(self, request: dict, expected: str, limit: float, car: int | None = None) -> dict:
        """Send ``request`` and take its answer, all within ``limit`` seconds from now; a
        failure names ``car``, whose call it was."""
        return self._answer(expected, self._send(request, limit, car), car)

    def _send(self, request: dict, limit: float, car: int | None) -> float:
        """Send ``request`` within ``limit`` seconds from now; that deadline."""
        if self.pid is None:
            raise RewardFailure("stopped", "The reward function is no longer running.", None, car)
        deadline = time.monotonic() + limit
        self.round_trips += 1
        try:
            write_by(self.requests, pack(request), deadline)
        except Late:
            raise self._late(car) from None
        except OSError:  # a broken pipe: the process is gone
            raise RewardFailure("crashed", self._ended(), None, car) from None
        return deadline

    def _answer(self, expected: str, deadline: float, car: int | None) -> dict:
        """The next reply, whole by ``deadline``: of type ``expected``, else the failure it
        tells (an error frame names its car; a failure of the process's, ``car``)."""
        try:
            reply = read_frame_by(self.replies, deadline, MAX_REPLY)
        except Late:
            raise self._late(car) from None
        except ProtocolError as error:
            self.stop()
            raise RewardFailure(
                "protocol",
                f"The reward function's process broke the protocol ({error}).",
                None,
                car,
            ) from None
        except OSError:  # the process is gone
            reply = None
        if reply is None:
            raise RewardFailure("crashed", self._ended(), None, car)
        self.printed.add(reply.get("log"), reply.get("log_dropped"))
        kind = reply.get("type")
        if kind == expected:
            return reply
        if kind == "error" and reply.get("kind") in KINDS:
            named = _int_or_none(reply.get("car"))
            raise RewardFailure(
                reply["kind"],
                str(reply.get("message", ""))[:500],
                _int_or_none(reply.get("line")),
                car if named is None else named,
            )
        self.stop()
        raise RewardFailure(
            "protocol", f"The reward function's process answered {kind!r}.", None, car
        )

    def _late(self, car: int | None) -> RewardFailure:
        """The failure of a call not answered by its deadline, the process stopped."""
        self.stop()
        message = f"The reward function took longer than {self.call_timeout:g} s; it was stopped."
        return RewardFailure("timeout", message, None, car)

    def _ended(self) -> str:
        status = self._reap()
        if status is not None and os.WIFSIGNALED(status):
            name = signal.Signals(os.WTERMSIG(status)).name
            reason = f"it was killed by {name}"
            if name == "SIGSEGV":
                reason += " (a crash, for example from ctypes)"
        else:
            code = os.WEXITSTATUS(status) if status is not None else "unknown"
            reason = f"it exited with status {code}; a reward function must return, not exit"
        return f"The reward function's process stopped: {reason}."

    def _reap(self) -> int | None:
        pid, self.pid = self.pid, None
        if pid is None:
            return None
        try:
            return os.waitpid(pid, 0)[1]
        except ChildProcessError:
            return None


# The reward process's side


def _fd_limit() -> int:
    """One past the highest descriptor this process may hold."""
    return resource.getrlimit(resource.RLIMIT_NOFILE)[0]


def _serve(
    parent: int, requests: int, replies: int, call_timeout: float, memory_allowance: int
) -> None:
    """Seal this process and answer the child's requests until it goes."""
    seal.die_with(parent)
    for fd in (0, 1):  # the worker's pipes are the child's alone
        os.close(fd)
    # And so is all else the child was handed: its slots in the machine's policy server above all
    # (sandbox.served), which the racer's code could otherwise map.
    for low, high in ((3, min(requests, replies)), (max(requests, replies) + 1, _fd_limit())):
        os.closerange(low, high)
    if abs(requests - replies) > 1:
        os.closerange(min(requests, replies) + 1, max(requests, replies))
    os.set_blocking(requests, True)
    for name in PRELOADED:
        importlib.import_module(name)
    # The racer's code sees only the environment the worker gave the child: what libraries add
    # for processes they would start (cv2's LD_LIBRARY_PATH names the install's path) goes, as
    # this process starts none, and every library here has read what it needs by now.
    os.environ.clear()
    os.environ.update(CHILD_ENVIRONMENT)
    host = _Host(os.fdopen(requests, "rb", buffering=0), replies, call_timeout)
    seal.enter_namespaces()
    seal.limit_resources(seal.current_address_space() + memory_allowance)
    seal.install_seccomp(read_fds=(requests,), write_fds=(replies, 2))
    host.run()


class _Host:
    def __init__(self, requests, replies: int, call_timeout: float) -> None:
        self.requests, self.replies = requests, replies
        self.call_timeout = call_timeout
        self.functions: list = []  # the racer's reward_function, a copy per car
        self.waypoints: tuple = ()
        self.printed = _Printed()
        sys.stdout = self.printed
        signal.signal(signal.SIGALRM, _alarm)

    def run(self) -> None:
        while (request := read_frame(self.requests)) is not None:
            handler = getattr(self, f"op_{request.get('op')}", None)
            if handler is None:
                self.send(_error("protocol", "unknown request", None))
                continue
            handler(request)

    def send(self, message: dict[str, Any]) -> None:
        message["log"], self.printed.lines = self.printed.lines, []
        message["log_dropped"], self.printed.dropped = self.printed.dropped, 0
        data = pack(message)
        while data:
            data = data[os.write(self.replies, data) :]

    def op_hello(self, request: dict) -> None:
        self.send({"type": "ready"})

    def op_waypoints(self, request: dict) -> None:
        self.waypoints = tuple(tuple(point) for point in request["waypoints"])
        self.send({"type": "waypoints"})

    def op_load(self, request: dict) -> None:
        source = request["source"]
        linecache.cache[FILENAME] = (len(source), None, source.splitlines(True), FILENAME)
        try:
            code = compile(source, FILENAME, "exec")
        except SyntaxError as error:
            self.send(_error("syntax", f"{error.msg}", error.lineno))
            return
        except (MemoryError, RecursionError):  # nested too deep for the parser
            self.send(_error("syntax", "The code is nested too deeply for Python to read.", None))
            return
        functions = []
        for _ in range(int(request.get("copies", 1))):
            namespace = {"__name__": "reward_function_module", "__builtins__": __builtins__}
            try:
                self._limited(exec, code, namespace)
            except BaseException as error:  # whatever the module did is reported
                kind = "import" if isinstance(error, ImportError) else "exception"
                self.send(_exception(kind, error, self.call_timeout))
                return
            functions.append(namespace.get("reward_function"))
            if not callable(functions[-1]):
                message = "The code must define reward_function(params)."
                self.send(_error("definition", message, None))
                return
        self.functions = functions
        self.send({"type": "loaded"})

    def op_call(self, request: dict) -> None:
        value = self._reward(request["car"], request["params"])
        self.send(value if isinstance(value, dict) else {"type": "reward", "value": value})

    def op_calls(self, request: dict) -> None:
        """A step of several cars: each car's call in turn, each within the time limit (its
        own alarm), its reward sent as it ends, so the child times each call from the last;
        the first that fails ends the step, its error naming its car."""
        for car, params in request["calls"]:
            value = self._reward(car, params)
            if isinstance(value, dict):
                self.send({**value, "car": car})
                return
            self.send({"type": "reward", "value": value, "car": car})

    def _reward(self, car: int, params: dict) -> float | dict[str, Any]:
        """The reward from car ``car``'s copy of the function, or the error frame of its
        failure. The value is checked within the call's time limit too: a number's own
        ``__float__`` or ``__repr__`` is the racer's code."""
        params = _params(params, self.waypoints)
        function = self.functions[car]
        try:
            return self._limited(lambda: checked_reward(function(params)))
        except RewardError as error:
            return _error("value", str(error), None)
        except BaseException as error:  # user code may raise anything
            return _exception("exception", error, self.call_timeout)

    def op_probe(self, request: dict) -> None:
        """Try what sealed code must not be able to do; report what got through."""
        escaped = seal.escapes(
            {
                "read a file": lambda: open(request["secret_path"]).read(),  # noqa: SIM115
                "connect to the network": lambda: (
                    __import__("socket").socket().connect(("127.0.0.1", int(request["port"])))
                ),
                "start a process": lambda: os.fork() == 0 and os._exit(0),
                "run a program": lambda: os.execv("/bin/true", ["true"]),  # noqa: S606
                "write a file": lambda: open("/tmp/pitlane-sandbox-probe", "w").write("x"),  # noqa: S108, SIM115
                "write to the worker": lambda: os.write(1, b"\0\0\0\1\x80"),
            }
        )
        self.send({"type": "probe", "escaped": escaped})

    def _limited(self, function, *args):
        """``function(*args)`` within the per-call time limit."""
        signal.setitimer(signal.ITIMER_REAL, self.call_timeout)
        try:
            return function(*args)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)


class _Printed(io.TextIOBase):
    """Standard output for user code: each printed line becomes a log message. At most
    ``MAX_LOG`` lines of ``MAX_LOG`` characters wait to be sent; lines past them are counted
    (``dropped``), not kept, so that a print flood costs neither memory nor the pipe."""

    def __init__(self) -> None:
        self.lines: list[str] = []
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


def _params(params: dict, waypoints: tuple) -> dict:
    """Params as the simulator makes them: a fresh list of the waypoints, locations as tuples."""
    params["waypoints"] = list(waypoints)
    if "objects_location" in params:
        params["objects_location"] = [tuple(point) for point in params["objects_location"]]
    return params


def _error(kind: str, message: str, line: int | None, **where: Any) -> dict[str, Any]:
    return {"type": "error", "kind": kind, "message": message[:500], "line": line, **where}


def _exception(kind: str, error: BaseException, timeout: float) -> dict[str, Any]:
    """An error message for what user code raised, with the line in the racer's code."""
    line = None
    for frame in traceback.extract_tb(error.__traceback__):
        if frame.filename == FILENAME:
            line = frame.lineno
    if isinstance(error, CallTimeout):
        return _error("timeout", f"The reward function took longer than {timeout:g} s.", line)
    if isinstance(error, MemoryError):
        return _error("memory", "The reward function ran out of memory.", line)
    if isinstance(error, SystemExit):
        return _error(kind, "The reward function called exit(); it must return a reward.", line)
    try:
        text = f"{type(error).__name__}: {error}"
    except BaseException:  # a message that cannot be printed is still an error
        text = type(error).__name__
    return _error(kind, text, line)
