"""Controller gains and limits, validated when the config loads (negative or NaN values refused)."""

from __future__ import annotations

import math
from typing import Annotated, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, model_validator

from records import CONTROLLER_NAMES, one_of
from records.plugins import CONTROLLER_GROUP, plugin_name

MPCSolver = Literal["rti", "sqp", "ipopt"]
"""`rti`: one Gauss-Newton SQP step per tick from the shifted last solution (acados' real-time
iteration), its QP solved by CasADi's qrqp; `sqp`: CasADi's sqpmethod with qrqp on the expanded
problem, iterated to convergence; `ipopt`: the interior-point reference (slower, same optimum)."""
MPC_SOLVERS: tuple[MPCSolver, ...] = get_args(MPCSolver)


VehicleModel = Literal["plant", "kinematic", "dynamic"]
"""The bicycle a controller's model assumes; `plant`: the one simulated (`sim.plant`)."""


class _Settings(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class PIDGains(_Settings):
    """Cascaded lateral PID and longitudinal speed PI (see controllers.lateral for the design)."""

    kp_lateral: float = Field(2.0, gt=0, description="lateral position gain [1/s]")
    ki_lateral: float = Field(0.6, ge=0, description="lateral integral gain [1/s^2]")
    kp_heading: float = Field(6.0, gt=0, description="heading gain [1/s]")
    model: VehicleModel = Field("plant", description="the bicycle the feedforward inverts")
    steering_rate: float = Field(0.5, gt=0, description="steering rate limit [rad/s]")
    max_steering: float = Field(math.pi / 4, gt=0, le=math.pi / 4, description="steering limit [rad]")
    kp_speed: float = Field(0.6, gt=0, description="speed gain [1/s]")
    ki_speed: float = Field(0.05, ge=0, description="speed integral gain [1/s^2]")
    max_acceleration: float = Field(2.0, gt=0, le=5, description="largest commanded acceleration [m/s^2]")


class MPCSettings(_Settings):
    """Joint steering + acceleration MPC on the bicycle model (controllers.mpc). `model` is the
    prediction model: highway-env's kinematic bicycle or its dynamic bicycle, whose parameters
    default to `BicycleVehicle`'s (highway_env/vehicle/dynamics.py: MASS = 1 kg, INERTIA_Z =
    MASS (LENGTH^2 + WIDTH^2) / 12 with 5 m x 2 m, FRICTION_FRONT = FRICTION_REAR = 15 N per wheel,
    two wheels per axle)."""

    model: VehicleModel = Field("plant", description="the prediction model")
    solver: Annotated[MPCSolver, one_of("MPC solver", MPC_SOLVERS)] = "rti"
    mass: float = Field(1.0, gt=0, description="dynamic model mass [kg]")
    yaw_inertia: float = Field(29 / 12, gt=0, description="dynamic model yaw inertia [kg m^2]")
    cornering_stiffness_front: float = Field(30.0, gt=0, description="front axle [N/rad]")
    cornering_stiffness_rear: float = Field(30.0, gt=0, description="rear axle [N/rad]")
    horizon: int = Field(16, ge=1, le=200, description="steps at the control rate (16: 1.07 s at 15 Hz)")
    weight_lateral: float = Field(200.0, ge=0)
    weight_heading: float = Field(20.0, ge=0)
    weight_speed: float = Field(1.0, ge=0)
    weight_acceleration: float = Field(0.1, ge=0)
    weight_steering: float = Field(1.0, ge=0)
    weight_steering_rate: float = Field(2000.0, ge=0)
    weight_jerk: float = Field(1.0, ge=0)
    max_steering: float = Field(math.pi / 4, gt=0, le=math.pi / 4, description="[rad]")
    max_steering_rate: float = Field(0.5, gt=0, description="soft comfort bound [rad/s]")
    max_lateral_acceleration: float = Field(
        2.0, gt=0, description="soft comfort bound on v psi' relative to the lane [m/s^2]"
    )
    weight_slack: float = Field(
        1e6, gt=0, description="quadratic penalty on comfort-bound violations (slack^2)"
    )
    max_acceleration: float = Field(2.0, gt=0, le=5, description="[m/s^2]")
    max_deceleration: float = Field(5.0, gt=0, le=5, description="[m/s^2]")
    max_solve_ms: float = Field(
        50.0,
        gt=0,
        description="solves slower than this are counted as slow (reported, never a fallback) [ms]",
    )
    max_iterations: int = Field(
        50, ge=1, description="a solve that has not converged in this many iterations falls back"
    )
    max_qp_iterations: int = Field(
        200, ge=1, description="qrqp's active-set iterations per QP (rti and sqp), beyond which it fails"
    )


class SteeringLimits(_Settings):
    """The steering limits every classic tracker applies (the PID's defaults)."""

    steering_rate: float = Field(0.5, gt=0, description="steering rate limit [rad/s]")
    max_steering: float = Field(math.pi / 4, gt=0, le=math.pi / 4, description="steering limit [rad]")


class PurePursuitSettings(SteeringLimits):
    """Pure pursuit (controllers.pure_pursuit): the look-ahead distance grows with the speed."""

    lookahead_time: float = Field(0.4, gt=0, description="look-ahead distance per speed [s]")
    min_lookahead: float = Field(4.0, gt=0, description="shortest look-ahead distance [m]")


class StanleyGains(SteeringLimits):
    """Stanley (controllers.stanley): cross-track gain, its low-speed softening, yaw-rate damping."""

    gain: float = Field(3.0, gt=0, description="cross-track gain k [1/s]")
    softening: float = Field(2.0, gt=0, description="k_soft, added to the speed [m/s]")
    yaw_damping: float = Field(0.0, ge=0, description="steering per yaw-rate error [s]")


class LQRSettings(SteeringLimits):
    """LQR on the lateral error dynamics (controllers.lqr), weights by Bryson's rule: each state or
    input is divided by the largest value it should take."""

    max_lateral_error: float = Field(0.05, gt=0, description="Bryson scale of the lateral error [m]")
    max_heading_error: float = Field(0.02, gt=0, description="Bryson scale of the heading error [rad]")
    max_slip: float = Field(0.01, gt=0, description="Bryson scale of the slip-angle correction [rad]")
    speed_step: float = Field(1.0, gt=0, le=10, description="spacing of the gain schedule [m/s]")


class ControllerConfig(_Settings):
    """The control layer: which tracker (`pid`, `mpc`, `pure-pursuit`, `stanley`, `lqr`, a name an
    installed package registers under the entry points `drivestack.controllers`, or a plug-in class
    `module.path:Class` / `file.py:Class`, see docs/plugins.md), its gains, the lane change (nominal
    duration, the course limit that stretches it at low speed, the speed below which none starts),
    the adaptive cruise (set speed, time gap, standstill gap, comfort deceleration) and emergency
    braking (`controllers.emergency`: deceleration, trigger time to collision)."""

    type: Annotated[str, plugin_name("controller", CONTROLLER_NAMES, CONTROLLER_GROUP)] = "pid"
    pid: PIDGains = PIDGains()
    mpc: MPCSettings = MPCSettings()
    pure_pursuit: PurePursuitSettings = PurePursuitSettings()
    stanley: StanleyGains = StanleyGains()
    lqr: LQRSettings = LQRSettings()
    lane_change_duration_s: float = Field(5.0, gt=0, description="[s]")
    set_speed_mps: float = Field(30.0, gt=0, le=40, description="[m/s]")
    time_gap_s: float = Field(1.5, ge=0, description="[s]")
    standstill_gap_m: float = Field(8.0, ge=0, description="[m]")
    comfort_decel_mps2: float = Field(3.0, gt=0, le=5, description="[m/s^2]")
    lane_change_max_course_deg: float = Field(
        12.0, gt=0, le=25, description="course a lane change's reference may ask for [deg]"
    )
    min_lane_change_speed_mps: float = Field(
        3.0, ge=0, le=40, description="no lane change starts below this speed [m/s]"
    )
    emergency_decel_mps2: float = Field(
        5.0, gt=0, le=5, description="emergency braking [m/s^2]; the plant brakes at most 5"
    )
    emergency_ttc_s: float = Field(
        1.0, ge=0, le=10, description="emergency braking below this time to collision [s]"
    )

    @model_validator(mode="after")
    def _emergency_beyond_comfort(self) -> ControllerConfig:
        if self.emergency_decel_mps2 < self.comfort_decel_mps2:
            raise ValueError(
                f"emergency_decel_mps2: must be >= comfort_decel_mps2 ({self.comfort_decel_mps2}), "
                f"got {self.emergency_decel_mps2}"
            )
        return self
