"""Reward functions run in the sandbox, and sandboxes that drive: what a reward function's call
comes to, and the episodes each car of a sandbox of several drives."""

import textwrap
from pathlib import Path

import msgpack
import numpy as np

from rl.wire import decode_array
from sandbox import MiB, Sandbox, SandboxFailure
from tests.services import parent_of

POLICY = {"algorithm": "clipped_ppo", "architecture": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"}


def driving(env: dict) -> Sandbox:
    """A sandbox that drives episodes in ``env`` as a rollout worker's does: with a policy."""
    return Sandbox(env=env, policy=POLICY, memory_allowance=1024 * MiB)


PARAMS = {"x": 1.0, "y": 2.0, "track_width": 0.76, "distance_from_center": 0.1}


def reward(body: str) -> str:
    """A reward function whose body is ``body``."""
    return "def reward_function(params):\n" + textwrap.indent(textwrap.dedent(body), "    ")


def outcome(source: str, params: dict = PARAMS, **settings) -> float | SandboxFailure:
    """What a call of ``source``'s reward function comes to: its reward, or how it failed."""
    with Sandbox(**settings) as sandbox:
        try:
            sandbox.load(source)
            return sandbox.call(params)
        except SandboxFailure as failure:
            return failure


def assert_stopped(result, kind: str, *fragments: str) -> None:
    """``result`` is a failure of ``kind`` whose words hold each of ``fragments``."""
    assert isinstance(result, SandboxFailure), f"the code ran and returned {result!r}"
    assert result.kind == kind, (result.kind, str(result))
    for fragment in fragments:
        assert fragment in str(result)


# The several cars' tests (test_cars, test_served_policy): their track, seed and reward function.
ENV = {"track": "pitlane-oval"}
SEED = 7
# Reading where the car is and how it moves, so that any difference shows; and counting its
# calls in a global, as DeepRacer reward functions that remember the step before do: each car's
# calls must reach a copy of their own, or the cars' counts would mix.
REWARD = """calls = 0

def reward_function(params):
    global calls
    calls += 1
    return params["progress"] + params["speed"] + abs(params["heading"]) / 100 + calls / 1000
"""


def episodes_by_car(sandbox: Sandbox, per_car: int) -> dict[int, list[dict]]:
    """Each car's first ``per_car`` episodes, driven as a rollout worker asks for them: every
    idle car starts one while more are wanted."""
    driven: dict[int, list[dict]] = {car: [] for car in range(sandbox.cars)}
    started = driving = 0
    while started < per_car * sandbox.cars or driving:
        start = min(sandbox.cars - driving, per_car * sandbox.cars - started)
        reply = sandbox.episode("explore", start=start)
        started += start
        driving = reply["driving"]
        driven[reply["car"]].append(msgpack.unpackb(reply["payload"]))
    return driven


def array(payload: dict, name: str) -> np.ndarray:
    """The float32 array ``name`` of an episode's ``payload``."""
    return decode_array(payload["arrays"][name], "float32", (None,))


def children_of(pid: int) -> list[int]:
    """The processes whose parent is ``pid``."""
    found = []
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            if parent_of(int(entry.name)) == pid:
                found.append(int(entry.name))
        except OSError:  # ended as it was read
            continue
    return found


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
