"""Stanley (Thrun et al., 2006; Hoffmann et al., 2007) on highway-env's kinematic bicycle, in the
lane frame.

Design. The heading error is theta = psi_ref - psi [rad] with psi_ref = atan(d_dot_ref / v) - beta_ss,
where beta_ss is the steady-state slip of the path's curvature (Hoffmann's psi_ss: on the path the
body points beta_ss inside its course). The cross-track error is measured at the front axle, L/2
ahead of the CoG, against where the front axle of a car on the reference would be:
e = d_ref - d + L/2 (sin psi_ref - sin psi) [m]. The
steering is

    delta = delta_ff + theta + atan(k e / (k_soft + v)) + k_yaw (r_ref - r),

with delta_ff the steering of the path's curvature (road and lateral profile), so a bend or a
lane change needs no error to be driven; k_soft keeps the cross-track term finite at low speed.
Linearised (delta ~ 2 beta, psi' = 2 v beta / L) the error obeys e'' + (v / L) e' + (k v / L) e = 0
for v >> k_soft: natural frequency sqrt(k v / L), damping 0.5 sqrt(v / (k L)).

Tuning. The feedforward carries the lane change, so the feedback only has to hold centimetres:
k = 3 1/s (natural frequency 2.4 rad/s and damping 0.41 at 10 m/s, 4.6 rad/s and 0.76 at 35 m/s)
is the stiffest gain that keeps the overshoot within 3 cm at 10-35 m/s (k = 1.2, damping 0.65 at
10 m/s, lags 4-6 cm behind a lane change). k_soft = 2 m/s. The yaw damping k_yaw [s] (steering per
rad/s of yaw-rate error, r_ref = v times the path curvature) is off by default: on the kinematic
plant it only slows the loop.
"""

from __future__ import annotations

import math

from controllers.bicycle import LENGTH
from controllers.config import StanleyGains
from controllers.steering import (
    MIN_SPEED,
    SteeringLimiter,
    path_curvature,
    slip_for_curvature,
    steering_for_slip,
)
from records import EgoState, Reference


class Stanley:
    """Steering [rad] from the front axle's cross-track and heading errors, fed forward by the
    path's curvature."""

    def __init__(self, gains: StanleyGains) -> None:
        self.gains = gains
        self.limiter = SteeringLimiter(gains)

    def reset(self) -> None:
        self.limiter.reset()

    def update(self, state: EgoState, reference: Reference, dt: float) -> float:
        gains, v = self.gains, max(state.speed, MIN_SPEED)
        curvature = path_curvature(state, reference)
        slip = slip_for_curvature(curvature)
        heading_reference = math.atan(reference.d_dot / v) - slip
        heading_error = heading_reference - state.heading
        front_offset = LENGTH / 2 * (math.sin(heading_reference) - math.sin(state.heading))
        cross_track = reference.d - state.d + front_offset
        yaw_rate_error = v * curvature - state.yaw_rate
        steering = (
            steering_for_slip(slip)
            + heading_error
            + math.atan(gains.gain * cross_track / (gains.softening + v))
            + gains.yaw_damping * yaw_rate_error
        )
        return self.limiter.limit(steering, dt)
