"""Controller gains and limits, validated when the config loads: every number has a range (negative,
NaN, infinite or absurdly large values refused), so a config that validates drives."""

from __future__ import annotations

import math
from typing import Annotated, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, model_validator

from common.plugins import CONTROLLER_GROUP, plugin_name
from controllers.weaving import WARY_S
from records import CONTROLLER_NAMES, one_of

MPCSolver = Literal["rti", "sqp", "ipopt"]
"""`rti`: one Gauss-Newton SQP step per tick from the shifted last solution (acados' real-time
iteration), its QP solved by CasADi's qrqp; `sqp`: CasADi's sqpmethod with qrqp on the expanded
problem, iterated to convergence; `ipopt`: the interior-point reference (slower, same optimum)."""
MPC_SOLVERS: tuple[MPCSolver, ...] = get_args(MPCSolver)


VehicleModel = Literal["plant", "kinematic", "dynamic"]
"""The bicycle a controller's model assumes; `plant`: the one simulated (`sim.plant`)."""

MAX_GAIN = 100.0
"""Upper bound of every feedback gain [1/s, 1/s^2]: far beyond any stable loop at 15 Hz, far below
where the commands overflow before they are clipped."""
MAX_STEERING_RATE = 10.0
"""Upper bound of every steering rate limit [rad/s] (a full lock-to-lock swing in 0.16 s)."""
MAX_WEIGHT = 1e6
"""Upper bound of every MPC cost weight (cost per squared unit of its term; the defaults reach 2000)."""
MIN_BRYSON_SCALE = 1e-3
"""Smallest Bryson scale of the LQR [m or rad]: its weight 1/scale^2 stays finite and the Riccati
equation solvable."""


class _Settings(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class PIDGains(_Settings):
    """Cascaded lateral PID and longitudinal speed PI (see controllers.lateral for the design)."""

    kp_lateral: float = Field(2.0, gt=0, le=MAX_GAIN, description="lateral position gain [1/s]")
    ki_lateral: float = Field(0.6, ge=0, le=MAX_GAIN, description="lateral integral gain [1/s^2]")
    kp_heading: float = Field(6.0, gt=0, le=MAX_GAIN, description="heading gain [1/s]")
    model: VehicleModel = Field("plant", description="the bicycle the feedforward inverts")
    steering_rate: float = Field(0.5, gt=0, le=MAX_STEERING_RATE, description="steering rate limit [rad/s]")
    max_steering: float = Field(math.pi / 4, gt=0, le=math.pi / 4, description="steering limit [rad]")
    kp_speed: float = Field(0.6, gt=0, le=MAX_GAIN, description="speed gain [1/s]")
    ki_speed: float = Field(0.05, ge=0, le=MAX_GAIN, description="speed integral gain [1/s^2]")
    max_acceleration: float = Field(2.0, gt=0, le=5, description="largest commanded acceleration [m/s^2]")


class MPCSettings(_Settings):
    """Joint steering + acceleration MPC on the bicycle model (controllers.mpc). `model` is the
    prediction model: highway-env's kinematic bicycle or its dynamic bicycle, whose parameters
    default to `BicycleVehicle`'s (highway_env/vehicle/dynamics.py: MASS = 1 kg, INERTIA_Z =
    MASS (LENGTH^2 + WIDTH^2) / 12 with 5 m x 2 m, FRICTION_FRONT = FRICTION_REAR = 15 N per wheel,
    two wheels per axle)."""

    model: VehicleModel = Field("plant", description="the prediction model")
    solver: Annotated[MPCSolver, one_of("MPC solver", MPC_SOLVERS)] = "rti"
    mass: float = Field(1.0, ge=1e-3, le=1e5, description="dynamic model mass [kg]")
    yaw_inertia: float = Field(29 / 12, ge=1e-3, le=1e6, description="dynamic model yaw inertia [kg m^2]")
    cornering_stiffness_front: float = Field(30.0, ge=1e-3, le=1e7, description="front axle [N/rad]")
    cornering_stiffness_rear: float = Field(30.0, ge=1e-3, le=1e7, description="rear axle [N/rad]")
    horizon: int = Field(16, ge=1, le=200, description="steps at the control rate (16: 1.07 s at 15 Hz)")
    weight_lateral: float = Field(200.0, ge=0, le=MAX_WEIGHT)
    weight_heading: float = Field(20.0, ge=0, le=MAX_WEIGHT)
    weight_speed: float = Field(1.0, ge=0, le=MAX_WEIGHT)
    weight_acceleration: float = Field(0.1, ge=0, le=MAX_WEIGHT)
    weight_steering: float = Field(1.0, ge=0, le=MAX_WEIGHT)
    weight_steering_rate: float = Field(2000.0, ge=0, le=MAX_WEIGHT)
    weight_jerk: float = Field(1.0, ge=0, le=MAX_WEIGHT)
    max_steering: float = Field(math.pi / 4, gt=0, le=math.pi / 4, description="[rad]")
    max_steering_rate: float = Field(
        0.5, gt=0, le=MAX_STEERING_RATE, description="soft comfort bound [rad/s]"
    )
    max_lateral_acceleration: float = Field(
        2.0, gt=0, le=20, description="soft comfort bound on v psi' relative to the lane [m/s^2]"
    )
    weight_slack: float = Field(
        1e6, gt=0, le=1e9, description="quadratic penalty on comfort-bound violations (slack^2)"
    )
    max_acceleration: float = Field(2.0, gt=0, le=5, description="[m/s^2]")
    max_deceleration: float = Field(5.0, gt=0, le=5, description="[m/s^2]")
    max_solve_ms: float = Field(
        50.0,
        gt=0,
        le=60_000,
        description="solves slower than this are counted as slow (reported, never a fallback) [ms]",
    )
    max_iterations: int = Field(
        50, ge=1, le=10_000, description="a solve that has not converged in this many iterations falls back"
    )
    max_qp_iterations: int = Field(
        200,
        ge=1,
        le=100_000,
        description="qrqp's active-set iterations per QP (rti and sqp), beyond which it fails",
    )


class SteeringLimits(_Settings):
    """The steering limits every classic tracker applies (the PID's defaults)."""

    steering_rate: float = Field(0.5, gt=0, le=MAX_STEERING_RATE, description="steering rate limit [rad/s]")
    max_steering: float = Field(math.pi / 4, gt=0, le=math.pi / 4, description="steering limit [rad]")


class PurePursuitSettings(SteeringLimits):
    """Pure pursuit (controllers.pure_pursuit): the look-ahead distance grows with the speed."""

    lookahead_time: float = Field(0.4, gt=0, le=10, description="look-ahead distance per speed [s]")
    min_lookahead: float = Field(4.0, ge=0.5, le=200, description="shortest look-ahead distance [m]")


class StanleyGains(SteeringLimits):
    """Stanley (controllers.stanley): cross-track gain, its low-speed softening, yaw-rate damping."""

    gain: float = Field(3.0, gt=0, le=MAX_GAIN, description="cross-track gain k [1/s]")
    softening: float = Field(2.0, gt=0, le=100, description="k_soft, added to the speed [m/s]")
    yaw_damping: float = Field(0.0, ge=0, le=10, description="steering per yaw-rate error [s]")


class LQRSettings(SteeringLimits):
    """LQR on the lateral error dynamics (controllers.lqr), weights by Bryson's rule: each state or
    input is divided by the largest value it should take."""

    max_lateral_error: float = Field(
        0.05, ge=MIN_BRYSON_SCALE, le=10, description="Bryson scale of the lateral error [m]"
    )
    max_heading_error: float = Field(
        0.02, ge=MIN_BRYSON_SCALE, le=1.5, description="Bryson scale of the heading error [rad]"
    )
    max_slip: float = Field(
        0.01, ge=MIN_BRYSON_SCALE, le=1.5, description="Bryson scale of the slip-angle correction [rad]"
    )
    speed_step: float = Field(1.0, ge=0.1, le=10, description="spacing of the gain schedule [m/s]")


class ControllerConfig(_Settings):
    """The control layer: which tracker (`pid`, `mpc`, `pure-pursuit`, `stanley`, `lqr`, a name an
    installed package registers under the entry points `drivestack.controllers`, or a plug-in class
    `module.path:Class` / `file.py:Class`, see docs/plugins.md), its gains, the lane change (nominal
    duration, the course limit that stretches it at low speed, the speed below which none starts),
    the adaptive cruise (set speed, time gap, standstill gap, comfort deceleration), emergency
    braking (`controllers.emergency`: deceleration, trigger time to collision) and how early both
    take a vehicle cutting in as a leader (`controllers.leaders`)."""

    type: Annotated[str, plugin_name("controller", CONTROLLER_NAMES, CONTROLLER_GROUP)] = "pid"
    pid: PIDGains = PIDGains()
    mpc: MPCSettings = MPCSettings()
    pure_pursuit: PurePursuitSettings = PurePursuitSettings()
    stanley: StanleyGains = StanleyGains()
    lqr: LQRSettings = LQRSettings()
    lane_change_duration_s: float = Field(5.0, ge=0.5, le=60, description="nominal lane-change duration [s]")
    set_speed_mps: float = Field(30.0, gt=0, le=40, description="[m/s]")
    time_gap_s: float = Field(1.5, ge=0, le=10, description="adaptive cruise time gap [s]")
    standstill_gap_m: float = Field(8.0, ge=0, le=100, description="adaptive cruise gap at standstill [m]")
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
    cut_in_lookahead_s: float = Field(
        1.0,
        ge=0,
        le=3,
        description="a vehicle whose sideways motion carries it into a lane within this time is "
        "that lane's leader for the cruise and emergency braking [s]; 0: only once it is in",
    )
    weaver_wary_s: float = Field(
        WARY_S,
        ge=0,
        le=60,
        description="a vehicle that turned back in the middle of a lane change is the cruise's leader "
        "for this long after, while ahead in a lane next to the one the ego keeps or heads for [s]; "
        "0: never",
    )

    @model_validator(mode="after")
    def _emergency_beyond_comfort(self) -> ControllerConfig:
        if self.emergency_decel_mps2 < self.comfort_decel_mps2:
            raise ValueError(
                f"emergency_decel_mps2: must be >= comfort_decel_mps2 ({self.comfort_decel_mps2}), "
                f"got {self.emergency_decel_mps2}"
            )
        return self
