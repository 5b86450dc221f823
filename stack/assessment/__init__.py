"""The safety assessment after UN R157: the full stack and R157's careful and competent driver
(`reference_driver`) on the same scripted scenario, point by point (`safety_assessment`)."""
