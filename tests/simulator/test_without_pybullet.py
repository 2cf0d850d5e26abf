"""The simulator where PyBullet cannot be imported (the device machine's Python 3.12 has no wheel
of it): a time trial needs no collision world, a race with boxes none until the car comes near
one, and then it says what it misses."""

import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

# Run in a fresh interpreter where ``import pybullet`` fails, as it does where it is not installed.
BLOCKED = """
import sys
sys.modules["pybullet"] = None
sys.modules["pybullet_utils"] = None
import gymnasium
import simulator
"""

TIME_TRIAL = (
    BLOCKED
    + """
for sensors in (["FRONT_FACING_CAMERA"], ["STEREO_CAMERAS", "LIDAR"]):
    env = gymnasium.make(simulator.ENV_ID, sensors=sensors, render_mode="rgb_array")
    observation, _ = env.reset(seed=1)
    for _ in range(3):
        observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert info["status"] == "in_progress", info["status"]
    assert env.render().shape == (480, 640, 3)
    if "LIDAR" in observation:
        assert (observation["LIDAR"] == 1.0).all(), "nothing on the track: every ray at its range"
    env.close()
print("drove", sorted(n for n, module in sys.modules.items() if "bullet" in n and module))
"""
)

OBJECT_AVOIDANCE = (
    BLOCKED
    + """
from simulator.samples import situations

near_object = situations("rookie-loop")[-1]
print(near_object.name, near_object.params["is_crashed"])
env = gymnasium.make(simulator.ENV_ID, race_type="OBJECT_AVOIDANCE").unwrapped
env.reset(seed=0)
box = env.traffic.actors[0]
env.car.place(box.x, box.y, box.yaw)
try:
    env.current_params()
except RuntimeError as error:
    print(type(error).__name__, error)
"""
)


def run(script: str) -> str:
    result = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_a_time_trial_builds_resets_steps_and_renders_without_pybullet():
    assert run(TIME_TRIAL).strip() == "drove []"


def test_boxes_need_pybullet_only_once_the_car_comes_near_one():
    near_object, touching = run(OBJECT_AVOIDANCE).splitlines()
    assert near_object == "near-object False"  # reward validation's samples: 0.6 m short of it
    assert touching.startswith(
        "WorldUnavailable Object avoidance and head-to-bot races need PyBullet"
    )


def test_pybullet_is_asked_wherever_its_answer_could_differ_from_nothing_near(monkeypatch):
    from simulator import world as world_module

    world = world_module.World()
    car = world.add_car(0.32, 0.20, 0.12)
    world.place(world.add_obstacle(0.5, 0.4, 0.3), 0.0, 0.0, 0.3)
    angles = np.linspace(-2.6, 2.6, 64)
    rays = np.column_stack([np.cos(angles), np.sin(angles)])
    rng = np.random.default_rng(0)
    touched = seen = 0
    for x, y, yaw in rng.uniform((-1.6, -1.6, -3.1), (1.6, 1.6, 3.1), (300, 3)):
        world.place(car, x, y, yaw)
        answers = world.car_touches(), world.cast_rays((x, y, 0.1), rays, 1.0)
        with monkeypatch.context() as always:
            always.setattr(world_module, "CONTACT_MARGIN", 100.0)  # PyBullet is asked every time
            assert world.car_touches() == answers[0]
            np.testing.assert_array_equal(world.cast_rays((x, y, 0.1), rays, 1.0), answers[1])
        touched += bool(answers[0])
        seen += bool((answers[1] < 1.0).any())
    assert touched > 10 and seen > 50  # the poses were near enough for both to matter
    world.close()
