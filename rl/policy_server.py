"""The machine's policy server: ``python -m rl.policy_server --socket PATH``, one per machine.

Every sandbox child that drives a rollout on the machine, of every rollout worker and every job,
acts through it (in the spirit of sample-factory's inference worker): the child writes its
cars' observations into slots of shared memory (``rl.slots``) and rings; the server runs one
batched forward pass per policy for every child that rang with it, and writes the actions back.
It holds each job's current policy once for the machine, on the GPU where there is one (one CUDA
context for the machine, rather than one a worker), and each car's random stream, so a car
drives the same episodes, step for step, as it would with the policy in its own child.

A rollout worker (``rl.policy_lease``) opens a connection a child: it asks for the child's
slots (the file and the socket come back with the answer, for the worker to hand the child) and
tells the server the weights the child drives with, sending them only where no other worker on
the machine has. Policies are shared by every child of the same job, algorithm, architecture,
spaces and weights, and forgotten when the last of those children goes. Every policy that has
children waiting is served once a round, the policies taking turns at going first, and a round
waits a moment for the children of the last: each job's cars get an equal share of the server.
A checkpoint's evaluation, which drives beside its job's next iteration with the same weights,
rides in the pass of that iteration's cars rather than pay one of its own for each of its steps.
On a CPU, a round's passes of several policies run at once on lanes of one thread each; on a
GPU, one after another.

What a child writes is checked before the network sees it; a child that writes nonsense is
refused in words and its socket closed, a child that dies or hangs only loses its own slots,
and nothing a child does reaches another child's slots or the server's policies. The server
ends itself once no worker has held a connection for ``--idle`` seconds.

Long because the server is one select loop whose parts (the workers' requests, the children's
rings, the batched passes, the idle end) share its state and are read together.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import hashlib
import logging
import os
import selectors
import socket
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field

import gymnasium
import numpy as np
import torch

import simulator
from rl.policies import Policy
from rl.slots import ANSWERED, ASK, HEADER_FIELDS, HOW, REFUSED, Layout, mapped
from rl.wire import ProtocolError, receive_message, send_message

logger = logging.getLogger("pitlane.policy_server")

IDLE = 300.0  # [s] without a worker's connection before the server ends itself
LOOK = 1.0  # [s] between looks at the idle clock while nothing happens
GATHER = 0.002  # [s] a round waits at most for the children of the last to ring again
# [s] an evaluating car waits at most this long after its job's exploring cars last asked for
# them to ask again, to ride in their pass: about ten of their steps on the 2-core box
RIDE = 0.05


@dataclass
class Shared:
    """A policy the server holds for the children of one job that drive with the same weights."""

    policy: Policy
    children: int = 0


@dataclass(eq=False)
class Child:
    """A sandbox child's slots: its worker's connection, its socket, the mapped file, its cars'
    random streams, and the policy it drives with."""

    worker: socket.socket
    job: int
    algorithm: str
    architecture: str
    spaces: tuple
    layout: Layout
    seeds: range
    ring: socket.socket | None = None
    views: dict = field(default_factory=dict)
    generators: dict = field(default_factory=dict)
    key: tuple | None = None  # of the policy it drives with
    rang: bool = False
    explored: float = 0.0  # [s] monotonic: when its cars last asked to explore


class Server:
    def __init__(
        self, path: str, device: str, idle: float = IDLE, lanes: int = 1, ride: float = RIDE
    ) -> None:
        self.path, self.device, self.idle, self.ride = path, device, idle, ride
        # Passes of several policies run at once on so many threads (each pass on one)
        self.lanes = concurrent.futures.ThreadPoolExecutor(lanes) if lanes > 1 else None
        self.selector = selectors.DefaultSelector()
        self.children: dict[socket.socket, Child | None] = {}  # by their worker's connection
        self.rings: dict[socket.socket, Child] = {}  # by the socket they ring on
        self.policies: dict[tuple, Shared] = {}
        self.spaces: dict[bytes, tuple] = {}  # the environments' spaces, by their settings
        self.quiet_since = time.monotonic()
        self.rounds = 0
        self.last_round: list[Child] = []  # the children answered in the last round
        self.riding: float | None = None  # [s] monotonic: when an evaluating car waits until
        self.stats = {"passes": 0, "rows": 0, "most_rows": 0, "pid": os.getpid()}
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        self.listener.bind(path)
        os.chmod(path, 0o600)
        self.inode, self.looked = os.stat(path).st_ino, time.monotonic()
        self.listener.listen(64)
        self.selector.register(self.listener, selectors.EVENT_READ, self._accept)

    def serve(self) -> None:
        """Serve until no worker has held a connection for ``idle`` seconds, or none holds
        one and the socket's path is gone (its machine's console stopped, or another server
        took the path over): the children it serves are served to their end."""
        while self.children or time.monotonic() - self.quiet_since < self.idle:
            self._handle(LOOK if self.riding is None else max(self.riding - time.monotonic(), 0))
            self._gather()
            self._guarded(self._answer_rings)
            if not self.children and not self._still_listening():
                logger.info("The socket %s is gone: the policy server ends", self.path)
                return
        logger.info("No worker for %g s: the policy server ends", self.idle)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.path)

    def _handle(self, timeout: float) -> None:
        """The events that come within ``timeout``: workers' requests, children's rings."""
        for key, _ in self.selector.select(timeout):
            if key.fileobj.fileno() != -1:  # not closed by an event before it this round
                self._guarded(key.data, key.fileobj)

    def _gather(self) -> None:
        """Once a child has rung, wait up to ``GATHER`` for the others answered last round: a
        child answered early in a round rings again before one answered late, and would
        otherwise be answered in every round while the late one waited out every other."""
        if not any(child.rang for child in self.rings.values()):
            return
        deadline = time.monotonic() + GATHER
        while (left := deadline - time.monotonic()) > 0 and any(
            not child.rang for child in self.last_round if child.ring is not None
        ):
            self._handle(left)

    @staticmethod
    def _guarded(handler, *arguments) -> None:
        """``handler(*arguments)``; a bug of its own is logged, never the end of the server and
        of every child it serves."""
        try:
            handler(*arguments)
        except Exception:
            logger.exception("The policy server failed in %s", handler.__name__)

    def _still_listening(self) -> bool:
        """Whether the socket's path is still this server's (looked at once a ``LOOK``)."""
        if time.monotonic() - self.looked < LOOK:
            return True
        self.looked = time.monotonic()
        try:
            return os.stat(self.path).st_ino == self.inode
        except FileNotFoundError:
            return False

    # The workers

    def _accept(self, listener: socket.socket) -> None:
        connection, _ = listener.accept()
        connection.settimeout(60.0)  # a worker is ours: a stalled one is a bug, not an attack
        self.selector.register(connection, selectors.EVENT_READ, self._from_worker)
        self.children[connection] = None  # its slots not yet opened

    def _from_worker(self, connection: socket.socket) -> None:
        try:
            message, _ = receive_message(connection)
        except (OSError, ProtocolError):
            message = None
        if message is None:
            self._forget(connection)
            return
        try:
            answer = self._worker_asks(connection, message)
        except (KeyError, TypeError, ValueError) as error:
            answer = {"type": "error", "message": f"a request out of protocol: {error}"[:300]}
        except Exception as error:  # the device's own: out of memory, its driver
            logger.exception("The policy server failed a worker's request")
            answer = {"type": "error", "message": f"the policy failed on {self.device}: {error}"}
        fds = answer.pop("fds", ())
        try:
            send_message(connection, answer, fds)
        except OSError:
            self._forget(connection)
        finally:
            for fd in fds:
                os.close(fd)

    def _worker_asks(self, connection: socket.socket, message: dict) -> dict:
        op = message["op"]
        if op == "stats":
            return {"type": "stats", **self.stats, "policies": len(self.policies)}
        if op == "open" and self.children.get(connection) is None:
            return self._open(connection, message)
        child = self.children.get(connection)
        if child is None:
            raise ValueError("no slots are open on this connection")
        if op == "weights":
            key = self._key(child, message["digest"])
            if key not in self.policies:
                return {"type": "weights", "have": False}
            self._drive_with(child, key)
            return {"type": "weights", "have": True}
        if op == "weights_data":
            data = bytes(message["data"])
            key = self._key(child, hashlib.sha256(data).hexdigest())
            if key not in self.policies:
                built = (child.algorithm, child.architecture, *child.spaces, self.device)
                policy = Policy.build(*built, loading=True)
                policy.load_published(data)
                self.policies[key] = Shared(policy)
            self._drive_with(child, key)
            return {"type": "weights", "have": True}
        raise ValueError(f"no request {op!r}")

    def _open(self, connection: socket.socket, message: dict) -> dict:
        spaces = self._spaces_of(message["env"])
        layout = Layout.of(*spaces, int(message["cars"]))
        seed = int(message["seed"])
        child = Child(
            connection,
            int(message["job"]),
            str(message["algorithm"]),
            str(message["architecture"]),
            spaces,
            layout,
            range(seed, seed + layout.cars),
        )
        memory = os.memfd_create(f"pitlane-slots-{child.job}", os.MFD_CLOEXEC)
        os.ftruncate(memory, layout.size)
        child.views = layout.views(mapped(memory, layout.size))
        child.generators = {seed: Policy.generator(seed) for seed in child.seeds}
        ring, given = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        ring.setblocking(False)
        child.ring = ring
        self.rings[ring] = child
        self.selector.register(ring, selectors.EVENT_READ, self._rung)
        self.children[connection] = child
        return {
            "type": "opened",
            "layout": layout.message(),
            "device": self.device,
            "pid": os.getpid(),
            "fds": (memory, given.detach()),
        }

    def _spaces_of(self, env: dict) -> tuple:
        """The observation and action spaces of the environment ``env`` describes."""
        key = hashlib.sha256(repr(sorted(env.items())).encode()).digest()
        if key not in self.spaces:
            made = gymnasium.make(simulator.ENV_ID, **env)
            try:
                self.spaces[key] = (made.observation_space, made.action_space)
            finally:
                made.close()
        return self.spaces[key]

    @staticmethod
    def _key(child: Child, digest: str) -> tuple:
        return (child.job, child.algorithm, child.architecture, child.layout, str(digest))

    def _drive_with(self, child: Child, key: tuple) -> None:
        if child.key == key:
            return
        self._let_go(child)
        child.key = key
        self.policies[key].children += 1

    def _let_go(self, child: Child) -> None:
        if child.key is not None:
            shared = self.policies[child.key]
            shared.children -= 1
            if shared.children == 0:
                del self.policies[child.key]
            child.key = None

    def _forget(self, connection: socket.socket) -> None:
        child = self.children.pop(connection, None)
        self.selector.unregister(connection)
        connection.close()
        if child is not None:
            self._let_go(child)
            self._close_ring(child)
        if not self.children:
            self.quiet_since = time.monotonic()

    # The children

    def _rung(self, ring: socket.socket) -> None:
        child = self.rings.get(ring)
        if child is None:
            return
        try:
            data = ring.recv(16)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if data == ASK:
            child.rang = True
        elif data:
            self._refuse(child, "it rang the policy server with something else than a request")
        else:  # the child has gone: its worker will close its connection
            self._close_ring(child)

    def _answer_rings(self) -> None:
        """Every child that rang, answered: one batched forward pass per policy of those that
        explore or evaluate (an evaluation's car drives with the weights the training cars of
        its job do, so it rides in their pass), each valuing child on its own."""
        together: dict[tuple, list] = defaultdict(list)
        self.last_round = [c for c in self.children.values() if c is not None and c.rang]
        for child in self.last_round:
            child.rang = False
            try:
                how, observations, seeds = self._read(child)
            except ProtocolError as error:
                self._refuse(child, str(error))
                continue
            if how in ("explore", "drive"):
                together[child.key].append((child, how, observations, seeds))
                if how == "explore":
                    child.explored = time.monotonic()
            else:
                try:
                    self._value(child, observations[0])
                except Exception as error:  # the device's own
                    logger.exception("The policy server failed a pass")
                    self._refuse(child, f"its policy failed on {self.device} ({error})"[:300])
        self._wait_to_ride(together)
        # Who is answered first rings again first, in time for the next round: the policies
        # take turns at going first, or the first would be answered twice as often.
        self.rounds += 1
        turns = list(together.items())
        turn = self.rounds % len(turns) if turns else 0
        # One pass a policy, never two of one at once: SB3 keeps a pass's distribution on the
        # policy's module, where a second pass would replace it before the first samples.
        passes = [(self.policies[key].policy, asked) for key, asked in turns[turn:] + turns[:turn]]
        if self.lanes is None or len(passes) < 2:
            for policy, asked in passes:
                self._answer_pass(asked, self._run_pass, policy, asked)
            return
        running = {self.lanes.submit(self._run_pass, *each): each[1] for each in passes}
        for done in concurrent.futures.as_completed(running):
            self._answer_pass(running[done], done.result)

    def _wait_to_ride(self, together: dict[tuple, list]) -> None:
        """Hold back the evaluating cars whose job's exploring cars drive but have not asked
        this round: they ask again within a few milliseconds, and the evaluating cars ride in
        their pass rather than pay a pass of their own for their few rows (a checkpoint's
        evaluation drives beside its job's next iteration: ``jobs.rollouts``). Once those have
        not asked for ``ride`` (``RIDE``), the evaluating cars go on alone."""
        self.riding = None
        now = time.monotonic()
        for key, asked in list(together.items()):
            if any(how == "explore" for _, how, _, _ in asked):
                continue
            explored = max((c.explored for c in self.rings.values() if c.key == key), default=0)
            if now - explored < self.ride:
                del together[key]
                for child, *_ in asked:
                    child.rang = True  # its request stands in its slots
                until = explored + self.ride
                self.riding = until if self.riding is None else min(self.riding, until)

    def _answer_pass(self, asked: list, run, *arguments) -> None:
        """Answer the children of one pass (``run(*arguments)``), or refuse them in words
        where it failed."""
        try:
            rows = run(*arguments)
        except Exception as error:  # the device's own: out of memory, its driver
            logger.exception("The policy server failed a pass")
            for child, *_ in asked:
                self._refuse(child, f"its policy failed on {self.device} ({error})"[:300])
            return
        self.stats["passes"] += 1
        self.stats["rows"] += rows
        self.stats["most_rows"] = max(self.stats["most_rows"], rows)
        for child, *_ in asked:
            self._answered(child)

    def _read(self, child: Child) -> tuple[str, list[dict], list[int]]:
        """(how, one observation a row, the rows' seeds) the child wrote, copied out of its
        slots and checked."""
        if child.key is None:
            raise ProtocolError("its cars asked for actions before its worker gave the weights")
        header = child.views["header"].copy()
        how, rows = int(header[0]), int(header[1])
        if not 0 <= how < len(HOW):
            raise ProtocolError("it asked for something the policy does not do")
        how_words = HOW[how]
        most = 1 if how_words == "value" else child.layout.cars
        if not 1 <= rows <= most:
            raise ProtocolError(f"it asked for {rows} rows of a policy serving {most}")
        seeds = [int(seed) for seed in header[HEADER_FIELDS : HEADER_FIELDS + rows]]
        if how_words == "explore" and (
            len(set(seeds)) != rows or not all(seed in child.generators for seed in seeds)
        ):
            raise ProtocolError("it named cars that are not its own")
        batch = {}
        for name, _, _ in child.layout.observations:
            rows_of = child.views[f"obs:{name}"][:rows].copy()
            if rows_of.dtype.kind == "f" and not np.isfinite(rows_of).all():
                raise ProtocolError("it wrote observations that are not finite numbers")
            batch[name] = rows_of
        observations = [{name: array[row] for name, array in batch.items()} for row in range(rows)]
        return how_words, observations, seeds

    def _run_pass(self, policy: Policy, asked: list) -> int:
        """One batched pass of ``policy`` for the children ``asked``, their answers written into
        their slots (on a lane's thread where there are several: it touches nothing else); the
        rows it ran."""
        exploring = [each for each in asked if each[1] == "explore"]
        driving = [each for each in asked if each[1] == "drive"]
        observations = [seen for _, _, rows, _ in exploring for seen in rows]
        generators = [child.generators[seed] for child, _, _, seeds in exploring for seed in seeds]
        driven = [seen for _, _, rows, _ in driving for seen in rows]
        actions, values, log_probs, deterministic = policy.act(observations, generators, driven)
        explored = {"actions": actions, "values": values, "log_probs": log_probs}
        for children, answers in ((exploring, explored), (driving, {"actions": deterministic})):
            start = 0
            for child, _, rows, _ in children:  # each child's rows, in the order they were run
                end = start + len(rows)
                for name, answer in answers.items():
                    if answer is not None:  # SAC has no values nor log-probabilities
                        child.views[name][: len(rows)] = answer[start:end]
                start = end
        return len(observations) + len(driven)

    def _value(self, child: Child, observation: dict) -> None:
        """A valuing child's answer (an episode's last observation, where time cut it short):
        the critic alone, on its own."""
        policy = self.policies[child.key].policy
        child.views["values"][0] = policy.value(observation)
        self._answered(child)

    def _answered(self, child: Child) -> None:
        try:
            child.ring.send(ANSWERED)
        except OSError:  # gone, or a child that never reads: it loses its slots
            self._close_ring(child)

    def _refuse(self, child: Child, reason: str) -> None:
        logger.warning("A sandbox child of job %s was refused: %s", child.job, reason)
        with contextlib.suppress(OSError):
            child.ring.send(REFUSED + f"The policy server refused the cars: {reason}.".encode())
        self._close_ring(child)

    def _close_ring(self, child: Child) -> None:
        if child.ring is not None:
            del self.rings[child.ring]
            self.selector.unregister(child.ring)
            child.ring.close()
            child.ring = None
            child.rang = False


def server_device(setting: str) -> str:
    """Where the server runs its policies for ``PITLANE_ROLLOUT_DEVICE``'s ``setting``: "auto"
    is "cuda" where PyTorch finds a GPU, else "cpu"."""
    if setting == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if setting == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            "PITLANE_ROLLOUT_DEVICE is cuda, but PyTorch finds no GPU on this simulation "
            "machine: set it to auto or cpu, or give the machine a GPU PyTorch can use."
        )
    return setting


def server_lanes(device: str) -> int:
    """Passes the server runs at once, each on one thread: on a GPU one (the GPU does the
    work); on a CPU one a core, so that several policies' passes run at once rather than in
    turn. PyTorch's threads inside a pass stay one: on
    the 2-core box, two rollout workers of 8 cars drove 412 steps/s where each pass took two
    threads against 787 with one (the second thread spun on the core a child simulates on)."""
    return 1 if device != "cpu" else len(os.sched_getaffinity(0))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--socket", required=True, help="the path the workers connect to")
    parser.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    parser.add_argument("--idle", type=float, default=IDLE, help="[s] idle before it ends")
    parser.add_argument("--lanes", type=int, default=0, help="passes at once (0: chosen)")
    parser.add_argument(
        "--ride", type=float, default=RIDE, help="[s] an evaluating car waits to ride at most"
    )
    arguments = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    try:
        device = server_device(arguments.device)
    except ValueError as error:
        sys.stderr.write(f"{error}\n")
        return 2
    torch.set_num_threads(1)
    lanes = arguments.lanes or server_lanes(device)
    server = Server(arguments.socket, device, arguments.idle, lanes, arguments.ride)
    logger.info("The policy server listens on %s, its policies on %s", arguments.socket, device)
    server.serve()
    return 0


if __name__ == "__main__":
    sys.exit(main())
