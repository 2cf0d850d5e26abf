"""The front wheels' steering hinge, turned as DeepRacer's version-5 car turns it (the loop and
every number's source: ``simulator.car.CarSpec``'s steering fields)."""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simulator.car import CarSpec


class Hinge:
    """The front wheels' steering hinge under its controller, one control period at a time, as
    Gazebo computes it: the command moves toward its target at most at the rate limit, the PID
    torque (the derivative of the error over one period) is clipped to the effort limit, and the
    hinge's velocity, then its angle, take one semi-implicit Euler step, as ODE's do.

    The derivative acts on the error, not on the hinge's velocity, so a new command kicks the
    hinge toward it within a few milliseconds, as far as the effort limit lets it; what is left
    closes with ``CarSpec.steering_time_constant``. With this hinge's small inertia the loop runs
    close to its stability limit (d / inertia * period = 1.89 of 2), so how far a change is met at
    once varies with its size: a 15° change is 62% met after 3 ms, a 30° one wholly after 10 ms."""

    def __init__(self, spec: CarSpec) -> None:
        self.spec = spec
        self.angle = 0.0  # [rad] left positive
        self.rate = 0.0  # [rad/s]
        self.command = 0.0  # [rad] after the rate limit
        self.error = 0.0  # [rad] at the last control period

    def turn(self, target: float, periods: int) -> float:
        """Run ``periods`` control periods toward ``target`` [rad]; the angle then."""
        spec = self.spec
        period = spec.control_period
        most = spec.steering_rate_limit * period
        kp, kd, effort = spec.steering_p, spec.steering_d / period, spec.steering_effort
        gain = period / spec.steering_inertia
        angle, rate, command, last = self.angle, self.rate, self.command, self.error
        for _ in range(periods):
            change = target - command
            command += most if change > most else -most if change < -most else change
            error = command - angle
            torque = kp * error + kd * (error - last)
            last = error
            torque = effort if torque > effort else -effort if torque < -effort else torque
            rate += torque * gain
            angle += rate * period
        self.angle, self.rate, self.command, self.error = angle, rate, command, last
        return angle

    def command_for(self, angle: float, periods: int, limit: float) -> float:
        """The target within ±``limit`` [rad] that brings the hinge nearest ``angle`` [rad] after
        ``periods``, from where it is now (it is left there): a bisection, since a larger target
        turns it further."""
        low, high = -limit, limit
        for _ in range(12):
            middle = (low + high) / 2
            if copy.copy(self).turn(middle, periods) < angle:
                low = middle
            else:
                high = middle
        return (low + high) / 2
