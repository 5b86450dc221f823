"""highway-env's dynamic bicycle, integrated stably at crawl speed.

`BicycleVehicle` takes one RK4 step per frame. Its yaw mode has the pole -2 (C_f a^2 + C_r b^2) /
(I_z v) = -155/v 1/s (linear tyres, C = 30 N/rad per axle, a = b = 2.5 m, I_z = 2.417 kg m^2), and RK4
is stable only for |lambda dt| <= 2.785: at 15 Hz the plant's own integration diverges below 3.7
m/s (seen as a car that drifts sideways with the steering held, or spins, at 2-3 m/s).
`StableBicycleVehicle` integrates the same equations with as many equal RK4 sub-steps as keep
|lambda dt| <= RK4_STEP_LIMIT; from 5.2 m/s up at 15 Hz that is one step, highway-env's own."""

from __future__ import annotations

import math

from highway_env.vehicle.dynamics import BicycleVehicle

YAW_POLE_GAIN = (
    2 * BicycleVehicle.FRICTION_FRONT * BicycleVehicle.LENGTH_A**2
    + 2 * BicycleVehicle.FRICTION_REAR * BicycleVehicle.LENGTH_B**2
) / BicycleVehicle.INERTIA_Z
"""|yaw pole| * v of the linearised dynamic bicycle [m/s^2] (155 for highway-env's defaults)."""
RK4_STEP_LIMIT = 2.0
"""Largest |lambda dt| per sub-step, inside RK4's real-axis stability limit of 2.785."""
LOW_SPEED = 1.0
"""Below this speed [m/s] highway-env replaces the tyres by plain damping (no stiff pole)."""


def substeps(speed: float, dt: float) -> int:
    """RK4 sub-steps for one frame of `dt` [s] at `speed` [m/s]."""
    return max(1, math.ceil(dt * YAW_POLE_GAIN / (max(abs(speed), LOW_SPEED) * RK4_STEP_LIMIT)))


class StableBicycleVehicle(BicycleVehicle):
    """`BicycleVehicle` with RK4 sub-steps below 5.2 m/s at 15 Hz (see the module docstring)."""

    def step(self, dt: float) -> None:
        count = substeps(self.speed, dt)
        for _ in range(count):
            super().step(dt / count)


def stabilised(vehicle: object) -> None:
    """Turn a `BicycleVehicle` (the dynamic plant's ego) into a `StableBicycleVehicle` in place."""
    if type(vehicle) is BicycleVehicle:
        vehicle.__class__ = StableBicycleVehicle
