"""While the trainer learns, the rollout worker's car waits: a viewer who picks another view then
gets that view of the waiting car at once, not nothing until the next episode."""

import time

import pytest

from jobs.rollouts import Viewing
from sandbox import MiB, Sandbox
from simulator.spectator import FRAME_INTERVAL
from training.rewards import EXAMPLES


class Publisher:
    """A stand-in for ``live.FramePublisher``: who watches is set by the test; offers are kept."""

    def __init__(self) -> None:
        self.views: set[str] = set()
        self.offered: list[dict] = []

    def watched(self, worker: int) -> set[str]:
        return set(self.views)

    def offer(self, frame: dict) -> None:
        self.offered.append(frame)


@pytest.fixture(scope="module")
def sandbox():
    policy = {"algorithm": "clipped_ppo", "architecture": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"}
    with Sandbox(
        env={"track": "pitlane-oval"}, policy=policy, memory_allowance=1024 * MiB
    ) as sandbox:
        sandbox.load(EXAMPLES[0].source)
        yield sandbox


@pytest.mark.slow
def test_a_view_chosen_while_the_car_waits_is_drawn_at_once_as_the_car_stands(sandbox):
    publisher = Publisher()
    viewing = Viewing(sandbox, publisher, worker=0)
    publisher.views = {"spectator"}
    viewing.update()
    summary = sandbox.episode("random", 0)["summary"]

    viewing.hold()  # the episodes are in: the car waits for the new policy
    publisher.views = {"spectator", "camera"}  # the racer picks the car's camera meanwhile
    viewing.update()
    viewing.hold()

    paused = {frame["view"]: frame for frame in publisher.offered if frame.get("paused")}
    assert set(paused) == {"spectator", "camera"}
    camera, spectator = paused["camera"], paused["spectator"]
    assert camera["jpeg"].startswith(b"\xff\xd8\xff")
    # The same moment: the end. Frames name DeepRacer's step (the reset is step 1, its prepare
    # step); the summary counts the steps driven.
    assert camera["step"] == spectator["step"] == summary["steps"] + 1
    assert camera["episode"] == spectator["episode"]


def test_frames_flow_again_once_the_new_policy_comes(sandbox):
    publisher = Publisher()
    viewing = Viewing(sandbox, publisher, worker=0)
    publisher.views = {"camera"}
    viewing.update()
    viewing.hold()
    viewing.resume()
    publisher.offered.clear()
    # Live frames come at most 15 a second of wall-clock time, and a random episode can be over
    # in less than one interval: begin one interval after the last frame, so it draws at least one.
    time.sleep(FRAME_INTERVAL)

    sandbox.episode("random", 0)

    assert publisher.offered and not any(frame.get("paused") for frame in publisher.offered)
