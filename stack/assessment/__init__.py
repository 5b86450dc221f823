"""The safety assessment after UN R157: the full stack and R157's careful and competent driver
(`stack.fault.reference_driver`, which the fault judge replays too) on the same scripted scenario,
point by point (`safety_assessment`)."""
