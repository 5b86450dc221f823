"""Pure pursuit (Coulter, 1992) on highway-env's kinematic bicycle, in the lane frame.

Design. A goal point lies a look-ahead distance l = max(min_lookahead, lookahead_time v) [m]
ahead along the lane, at the reference offset the car is due to have when it gets there,
d_ref(t + l / v). In the frame of the lane's tangent at the car it sits at x = l, y = d_ref - d +
kappa l^2 / 2 (the road's bend over l). The arc tangent to the body's heading psi that reaches the
goal has curvature 2 sin(alpha) / |goal|, alpha = atan2(y, x) - psi; the steering that drives that
arc on the kinematic bicycle follows (`controllers.steering`). (Measuring alpha from the course psi
+ beta instead feeds the steering back on itself with gain L / l: it chatters below l = L = 5 m.)

Tuning. The only gain is the look-ahead. Linearised, d'' + (2 v / l) d' + (2 v^2 / l^2) d = 0: with
l proportional to v the damping is 0.71 at every speed and the natural frequency sqrt(2) /
lookahead_time. There is no feedforward: the goal point leads the reference, so the car cuts the
inside of each of the lane change's two curves, lagging at first and overshooting the target lane
on bends; both grow with l. 0.4 s (min 4 m) is the longest look-ahead within the 4 cm RMS target at
10 m/s (kinematic plant: RMS 3.9 cm at 10 m/s, overshoot 2.3 cm at 35 m/s on the 1000 m bend;
0.5 s gives 4.9 cm and 3.3 cm); below 10 m/s the 4 m floor dominates and the lag grows (13 cm RMS at
5 m/s; a shorter floor rings against the steering rate limit). BENCHMARKS.md (issue 33) has the
table. On the dynamic plant no slip is modelled.
"""

from __future__ import annotations

import math

from controllers.config import PurePursuitSettings
from controllers.steering import MIN_SPEED, SteeringLimiter, slip_for_curvature, steering_for_slip
from records import EgoState, Reference


class PurePursuit:
    """Steering [rad] towards a goal point on the reference, `lookahead_time` [s] ahead."""

    def __init__(self, settings: PurePursuitSettings) -> None:
        self.settings = settings
        self.limiter = SteeringLimiter(settings)

    def reset(self) -> None:
        self.limiter.reset()

    def lookahead(self, speed: float) -> float:
        """The look-ahead distance [m] at `speed` [m/s]."""
        return max(self.settings.min_lookahead, self.settings.lookahead_time * speed)

    def update(self, state: EgoState, reference: Reference, dt: float) -> float:
        v = max(state.speed, MIN_SPEED)
        distance = self.lookahead(v)
        arrival = reference.time + distance / v
        goal_d = reference.d if reference.lateral is None else reference.lateral.sample(arrival)[0]
        x, y = distance, goal_d - state.d + state.curvature * distance**2 / 2
        alpha = math.atan2(y, x) - state.heading
        curvature = 2 * math.sin(alpha) / math.hypot(x, y)
        return self.limiter.limit(steering_for_slip(slip_for_curvature(curvature)), dt)
