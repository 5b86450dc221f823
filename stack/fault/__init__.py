"""Who is to blame, as UN R157 sees it: R157's careful and competent driver (`reference_driver`),
replayed in the ego's place to decide a collision's fault (`preventability`), and the cause of
each emergency braking (`emergency_causes`). The safety monitor and the batch use them; the safety
assessment drives the reference driver on its scripted scenarios."""
