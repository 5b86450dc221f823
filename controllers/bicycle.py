"""The kinematic bicycle of highway-env 1.12 (`vehicle/kinematics.py`), as a pure function and as
a CasADi symbolic function: one model shared by the MPC, the tests and offline tracking; and its
dynamic bicycle with linear tyres (`vehicle/dynamics.py`, `BicycleVehicle`) as a CasADi function.

CoG at mid-length: beta = atan(tan(delta) / 2); x' = v cos(psi + beta), y' = v sin(psi + beta),
psi' = v sin(beta) / (L / 2), v' = a; integrated with forward Euler, position first with the old
heading, as highway-env does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

LENGTH = 5.0
"""Vehicle length = wheelbase of highway-env's bicycle [m]."""
WIDTH = 2.0
"""[m]"""
MASS = 1.0
"""highway-env's `BicycleVehicle.MASS` [kg] (its tyre forces are scaled to it)."""
CORNERING_STIFFNESS = 30.0
"""Per axle, front and rear: 2 x `BicycleVehicle.FRICTION_FRONT` (15 N/rad) [N/rad]."""
INERTIA_Z = MASS * (LENGTH**2 + WIDTH**2) / 12
"""Yaw inertia of `BicycleVehicle`, a uniform L x W rectangle [kg m^2] (2.417)."""
YAW_POLE_SPEED = 2 * CORNERING_STIFFNESS * (LENGTH / 2) ** 2 / INERTIA_Z
"""The dynamic bicycle's yaw-rate pole is -YAW_POLE_SPEED / v [1/s]: (a^2 C_f + b^2 C_r) / I_z
with a = b = L / 2 [m/s] (155.2)."""
SLIP_GRADIENT = MASS * (LENGTH / 2) / (CORNERING_STIFFNESS * LENGTH)
"""Steady sideslip of the dynamic bicycle below the kinematic one per lateral acceleration:
beta_dynamic - beta_kinematic = -SLIP_GRADIENT v r (m a / (C_r L), Rajamani 2.21-2.22) [s^2/m]."""


@dataclass(frozen=True)
class BicycleState:
    """Position x, y [m], heading psi [rad], speed v [m/s]."""

    x: float
    y: float
    psi: float
    v: float


def slip_angle(steering: float) -> float:
    """beta [rad] of the CoG for a front steering angle [rad]."""
    return math.atan(0.5 * math.tan(steering))


def step(state: BicycleState, acceleration: float, steering: float, dt: float) -> BicycleState:
    """One forward-Euler step of `dt` seconds, bit-for-bit highway-env's `Vehicle.step` (without
    its speed clipping at +-40 m/s)."""
    beta = slip_angle(steering)
    return BicycleState(
        x=state.x + state.v * math.cos(state.psi + beta) * dt,
        y=state.y + state.v * math.sin(state.psi + beta) * dt,
        psi=state.psi + state.v * math.sin(beta) / (LENGTH / 2) * dt,
        v=state.v + acceleration * dt,
    )


def lateral_acceleration(speed: float, steering: float) -> float:
    """Centripetal acceleration v * psi' [m/s^2] for a steady steering angle."""
    return speed**2 * math.sin(slip_angle(steering)) / (LENGTH / 2)


def symbolic_lane_model() -> ca.Function:
    """CasADi `f(state, input, curvature, dt) -> next state` in a lane frame: state (d, psi, v)
    with d the lateral offset and psi the heading relative to the lane, input (a, delta);
    curvature [1/m] turns the frame (psi' loses kappa * s'). Forward Euler, as the plant."""
    state, control = ca.SX.sym("state", 3), ca.SX.sym("input", 2)
    curvature, dt = ca.SX.sym("curvature"), ca.SX.sym("dt")
    d, psi, v = state[0], state[1], state[2]
    beta = ca.atan(0.5 * ca.tan(control[1]))
    s_dot = v * ca.cos(psi + beta) / (1 - curvature * d)
    derivative = ca.vertcat(
        v * ca.sin(psi + beta),
        v * ca.sin(beta) / (LENGTH / 2) - curvature * s_dot,
        control[0],
    )
    return ca.Function("bicycle", [state, control, curvature, dt], [state + dt * derivative])


def symbolic_dynamic_lane_model(
    mass: float, yaw_inertia: float, stiffness_front: float, stiffness_rear: float
) -> ca.Function:
    """CasADi `f(state, input, curvature, dt) -> next state` of highway-env's `BicycleVehicle` in a
    lane frame: state (d [m], psi [rad], v [m/s], v_y [m/s], r [rad/s]) with v and v_y the body
    speeds and r the yaw rate, input (a [m/s^2], delta [rad]). Tyre forces are stiffness [N/rad]
    x slip angle, CoG at mid-length; mass [kg] and yaw inertia [kg m^2] as the plant's. One RK4
    step of dt, as `BicycleVehicle.step` takes one per tick (its |v| < 1 m/s damping is left out)."""
    state, control = ca.SX.sym("state", 5), ca.SX.sym("input", 2)
    curvature, dt = ca.SX.sym("curvature"), ca.SX.sym("dt")
    half = LENGTH / 2

    def derivative(x: ca.SX) -> ca.SX:
        d, psi, v, v_y, r = x[0], x[1], x[2], x[3], x[4]
        front = stiffness_front * (control[1] - ca.atan2(v_y + half * r, v))
        rear = -stiffness_rear * ca.atan2(v_y - half * r, v)
        s_dot = (v * ca.cos(psi) - v_y * ca.sin(psi)) / (1 - curvature * d)
        return ca.vertcat(
            v * ca.sin(psi) + v_y * ca.cos(psi),
            r - curvature * s_dot,
            control[0],
            (front + rear) / mass - r * v,
            half * (front - rear) / yaw_inertia,
        )

    k1 = derivative(state)
    k2 = derivative(state + dt / 2 * k1)
    k3 = derivative(state + dt / 2 * k2)
    k4 = derivative(state + dt * k3)
    next_state = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("dynamic_bicycle", [state, control, curvature, dt], [next_state])
