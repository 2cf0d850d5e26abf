"""Check ``simulator.steering.Hinge`` against a full rigid-body car: DeepRacer's own URDF and wheel
meshes in PyBullet on a plane, its wheels and steering hinges driven by the loops that
gazebo_ros_control runs for a version-5 car, at Gazebo's 1 ms step. It prints, for steering
changes of 2° to 30° made while the car rolls at 1.5 m/s, the hinge's angle after 1, 3, 10, 67
(one control step) and 600 ms, in PyBullet and in our hinge.

    python scripts/check_steering.py --simapp PATH   # a deepracer-simapp checkout at 2fc2d75c

Nothing of simapp is copied into Pitlane: its URDF and meshes are read from ``PATH`` and written,
with their ``package://`` paths resolved and xacro's conditionals dropped, to a temporary folder.
Not a test (it needs that checkout); docs/simulator.md quotes its figures.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from simulator.car import CarSpec  # noqa: E402
from simulator.steering import Hinge  # noqa: E402

URDF = "bundle/urdf/deepracer/deepracer_single_cam.urdf"
MESHES = "bundle/meshes/deepracer"
STEP = 0.001  # [s] Gazebo's physics step, and the loops' period
SPEED = 1.5  # [m/s] while the steering changes
CHANGES = (2.0, 5.0, 10.0, 15.0, 30.0)  # [deg]
SAMPLES = (1, 3, 10, 67, 600)  # [ms] after the change


def car_urdf(simapp: Path, folder: Path) -> Path:
    """The single-camera car's URDF as PyBullet can read it, in ``folder``."""
    text = (simapp / URDF).read_text()
    text = re.sub(r"\s*</?xacro:(unless|if)\b[^>]*>", "", text)
    text = text.replace(
        "package://deepracer_simulation_environment/meshes/deepracer/", str(simapp / MESHES) + "/"
    )
    path = folder / "car.urdf"
    path.write_text(text)
    return path


class Rig:
    """The car in PyBullet with the version-5 loops: each wheel p * (target - speed) (p 1.0 rear,
    0.5 front), each hinge p * error + d * d(error)/dt toward a command rate-limited at 100 rad/s,
    every torque clipped at 10 N m."""

    def __init__(self, urdf: Path) -> None:
        import pybullet

        self.p = p = pybullet
        p.connect(p.DIRECT)
        p.setGravity(0, 0, -9.81)
        p.setTimeStep(STEP)
        plane = p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE))
        p.changeDynamics(plane, -1, lateralFriction=1.0)  # PyBullet multiplies: the wheels' 0.5
        self.car = car = p.loadURDF(str(urdf), [0, 0, 0.05], flags=p.URDF_USE_INERTIA_FROM_FILE)
        self.joints = {p.getJointInfo(car, j)[1].decode(): j for j in range(p.getNumJoints(car))}
        for j in range(p.getNumJoints(car)):
            p.setJointMotorControl2(car, j, p.VELOCITY_CONTROL, force=0)  # no built-in motors
            wheel = "wheel" in p.getJointInfo(car, j)[12].decode()
            p.changeDynamics(
                car,
                j,
                lateralFriction=0.5 if wheel else 0.0,
                jointDamping=0.0,
                linearDamping=0.0,
                angularDamping=0.0,
            )
        p.changeDynamics(car, -1, linearDamping=0.0, angularDamping=0.0)
        self.spec = spec = CarSpec()
        self.wheels = {
            f"{side}_{axle}_wheel_joint": gain
            for side in ("left", "right")
            for axle, gain in (("rear", spec.rear_wheel_gain), ("front", spec.front_wheel_gain))
        }
        self.hinges = {f"{side}_steering_hinge_joint": [0.0, 0.0] for side in ("left", "right")}

    def angle(self) -> float:
        """[deg] the left hinge's angle."""
        return math.degrees(
            self.p.getJointState(self.car, self.joints["left_steering_hinge_joint"])[0]
        )

    def tick(self, speed: float, steering: float) -> None:
        p, spec = self.p, self.spec
        for name, gain in self.wheels.items():
            rate = p.getJointState(self.car, self.joints[name])[1]
            torque = gain * (speed / spec.command_radius - rate)
            p.setJointMotorControl2(
                self.car, self.joints[name], p.TORQUE_CONTROL, force=max(-10.0, min(10.0, torque))
            )
        most = spec.steering_rate_limit * STEP
        for name, state in self.hinges.items():
            command, last = state
            command += max(-most, min(most, steering - command))
            error = command - p.getJointState(self.car, self.joints[name])[0]
            torque = spec.steering_p * error + spec.steering_d * (error - last) / STEP
            state[:] = command, error
            effort = spec.steering_effort
            p.setJointMotorControl2(
                self.car,
                self.joints[name],
                p.TORQUE_CONTROL,
                force=max(-effort, min(effort, torque)),
            )
        p.stepSimulation()


def ours(change: float) -> list[float]:
    hinge = Hinge(CarSpec())
    angles, done = [], 0
    for sample in SAMPLES:
        angles.append(math.degrees(hinge.turn(math.radians(change), sample - done)))
        done = sample
    return angles


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--simapp", type=Path, required=True, help="a deepracer-simapp checkout")
    arguments = parser.parse_args()
    if not (arguments.simapp / URDF).is_file():
        parser.error(f"no {URDF} under {arguments.simapp}: is it a deepracer-simapp checkout?")
    with tempfile.TemporaryDirectory() as folder:
        rig = Rig(car_urdf(arguments.simapp.resolve(), Path(folder)))
        for _ in range(2000):  # 2 s to roll up to speed, straight ahead
            rig.tick(SPEED, 0.0)
        rolling = rig.p.saveState()
        print(f"{'change':>8}" + "".join(f"{f'{ms} ms':>16}" for ms in SAMPLES))
        for change in CHANGES:
            rig.p.restoreState(rolling)
            for state in rig.hinges.values():
                state[:] = 0.0, 0.0
            pybullet_angles, done = [], 0
            for sample in SAMPLES:
                for _ in range(sample - done):
                    rig.tick(SPEED, math.radians(change))
                pybullet_angles.append(rig.angle())
                done = sample
            cells = "".join(
                f"{a:>7.2f} / {b:>6.2f}" for a, b in zip(pybullet_angles, ours(change), strict=True)
            )
            print(f"{change:>7.0f}°{cells}   (PyBullet / ours, degrees)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
