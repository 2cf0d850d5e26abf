"""The dynamic car's physics: invariants that hold whatever the numbers, not figures copied from a
run. The car is DeepRacer's Gazebo car (simulator/car.py): friction-limited tyres, a wheel speed
controller, a steering hinge turned by DeepRacer's PID loop."""

import itertools
import math

import gymnasium
import numpy as np
import pytest

import simulator
from simulator.car import GRAVITY, Car, CarSpec
from simulator.steering import Hinge

DT = 1 / 15  # [s] one control step


def drive(car: Car, speed: float, steering: float, seconds: float) -> list[tuple[float, ...]]:
    """Hold the commands for ``seconds``; the car's (x, y, yaw, speed) after each step."""
    states = []
    for _ in range(round(seconds / DT)):
        car.step(speed, steering, DT)
        states.append((car.x, car.y, car.yaw, car.speed))
    return states


def turning_radius(car: Car, speed: float, steering: float) -> float:
    """[m] of the circle the rear axle settles on: drive 10 s, fit a circle to the last 5 s
    (least squares: x² + y² = 2ax + 2by + c, radius² = c + a² + b²)."""
    states = drive(car, speed, steering, 10.0)[-75:]
    points = np.array([(x, y) for x, y, _, _ in states])
    design = np.column_stack([2 * points, np.ones(len(points))])
    (a, b, c), *_ = np.linalg.lstsq(design, (points**2).sum(axis=1), rcond=None)
    return float(math.sqrt(c + a * a + b * b))


def test_a_car_at_rest_stays_at_rest():
    car = Car()
    car.place(1.0, -2.0, 0.5)
    for steering in (0.0, 30.0, -30.0):
        drive(car, 0.0, steering, 2.0)
        assert (car.x, car.y, car.yaw) == pytest.approx((1.0, -2.0, 0.5), abs=1e-9)
        assert car.speed == pytest.approx(0.0, abs=1e-9)


def test_on_a_straight_it_speeds_up_to_its_wheels_speed_no_faster_than_the_grip_allows():
    spec = CarSpec()
    car = Car(spec)
    speeds = [state[3] for state in drive(car, 2.0, 0.0, 3.0)]
    target = spec.wheel_target(2.0)
    assert all(b >= a - 1e-9 for a, b in itertools.pairwise(speeds))  # no overshoot
    assert speeds[-1] == pytest.approx(target, rel=1e-3)
    assert max(speeds) <= target + 1e-6
    accelerations = np.diff([0.0, *speeds]) / DT
    assert accelerations.max() <= spec.friction * GRAVITY * 1.001  # four-wheel drive: mu * g
    # The wheel turns at speed / 0.035 rad/s on a 0.036 m tread; the joint's limit caps it.
    assert target == pytest.approx(2.0 * 0.036 / 0.035)
    assert spec.top_speed == pytest.approx(100 * 0.036)


def test_braking_takes_the_time_the_grip_asks():
    spec = CarSpec()
    car = Car(spec)
    drive(car, 3.0, 0.0, 2.0)
    fast = car.speed
    speeds = [state[3] for state in drive(car, 0.1, 0.0, 2.0)]
    decelerations = -np.diff([fast, *speeds]) / DT
    assert decelerations.max() <= spec.friction * GRAVITY * 1.25  # weight moves onto the front
    assert decelerations.max() >= spec.friction * GRAVITY * 0.75
    assert speeds[-1] == pytest.approx(spec.wheel_target(0.1), rel=1e-3)


@pytest.mark.parametrize("degrees", [30.0, -12.0, 4.0, 0.5])
def test_the_steering_hinge_reaches_its_command_and_holds_it(degrees):
    hinge = Hinge(CarSpec())
    hinge.turn(math.radians(degrees), 5000)  # 5 s: ten of the residual's time constants
    assert math.degrees(hinge.angle) == pytest.approx(degrees, abs=0.01)
    held = hinge.angle
    hinge.turn(math.radians(degrees), 1000)
    assert hinge.angle == pytest.approx(held, abs=1e-4)


@pytest.mark.parametrize("degrees", [15.0, 30.0])
def test_a_new_command_kicks_the_hinge_on_at_once(degrees):
    # The loop differentiates the error, so a change's first periods push the hinge as hard as
    # the effort limit allows: within one control step it is past half the change, where a servo
    # damped on the hinge's own velocity (d / p = 0.5 s) would be 1 - exp(-DT / 0.5) = 12% there.
    spec = CarSpec()
    hinge = Hinge(spec)
    hinge.turn(math.radians(degrees), round(DT / spec.control_period))
    assert hinge.angle / math.radians(degrees) > 0.5
    assert 1 - math.exp(-DT / spec.steering_time_constant) < 0.13


def test_the_hinge_is_pushed_no_harder_than_its_joint_allows():
    spec = CarSpec()
    hinge = Hinge(spec)
    rng = np.random.default_rng(0)
    most_rate_change = spec.steering_effort * spec.control_period / spec.steering_inertia
    most_command_change = spec.steering_rate_limit * spec.control_period
    for target in rng.uniform(-0.5, 0.5, 300):
        rate, command = hinge.rate, hinge.command
        hinge.turn(float(target), 1)
        assert abs(hinge.rate - rate) <= most_rate_change * (1 + 1e-9)
        assert abs(hinge.command - command) <= most_command_change * (1 + 1e-9)


def test_the_car_steers_with_its_hinge():
    car = Car()
    car.step(0.5, 30.0, DT)
    hinge = Hinge(car.spec)
    hinge.turn(math.radians(30.0), round(DT / car.spec.control_period))
    assert car.steering == pytest.approx(hinge.angle, abs=1e-12)


@pytest.mark.parametrize("steering", [10.0, 20.0, 30.0])
def test_a_slow_steady_turn_follows_the_kinematic_radius(steering):
    spec = CarSpec()
    car = Car(spec)
    radius = turning_radius(car, 0.5, steering)
    assert not car.sliding
    assert radius == pytest.approx(spec.wheelbase / math.tan(math.radians(steering)), rel=0.03)


def test_a_turn_too_fast_for_the_grip_slides_wide_or_spins():
    spec = CarSpec()
    kinematic = spec.wheelbase / math.tan(math.radians(15.0))
    car = Car(spec)
    radius = turning_radius(car, 3.0, 15.0)
    assert car.sliding
    # The tyres give at most mu * g sideways, so the car runs wide of the radius it steers for
    # (understeer), or the rear steps out and it yaws faster than its path turns (a spin).
    path_speed = math.hypot(car.speed, car.lateral_speed)
    spun = abs(car.yaw_rate) > 1.2 * path_speed / radius
    assert radius > 2 * kinematic or spun


def slide_speed(spec: CarSpec, steering: float = 10.0) -> float:
    """[m/s] the lowest commanded speed, in steps of 0.1 m/s, at which a steady turn slides."""
    for tenths in range(5, 41):
        car = Car(spec)
        drive(car, tenths / 10, steering, 6.0)
        if car.sliding:
            return tenths / 10
    return math.inf


def test_less_friction_slides_earlier():
    grippy, slippery = slide_speed(CarSpec()), slide_speed(CarSpec(friction=0.25))
    assert slippery < grippy < math.inf
    # Steady cornering at the limit: v^2 / R = mu * g, so the speed scales with sqrt(mu).
    assert slippery / grippy == pytest.approx(math.sqrt(0.5), abs=0.1)


def test_the_same_seed_drives_the_same_trajectory():
    runs = []
    for _ in range(2):
        env = gymnasium.make(
            simulator.ENV_ID,
            track="hairpin-alley",
            action_space={
                "steering_angle": {"low": -30, "high": 30},
                "speed": {"low": 0.5, "high": 4},
            },
        )
        env.reset(seed=7)
        env.action_space.seed(7)
        rows = []
        for _ in range(300):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            car = env.unwrapped.car
            rows.append((car.x, car.y, car.yaw, car.speed, car.lateral_speed, car.yaw_rate))
            if terminated or truncated:
                env.reset()
        env.close()
        runs.append(rows)
    assert runs[0] == runs[1]
