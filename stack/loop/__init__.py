"""The closed loop: one episode as a steppable object (`ClosedLoop`), the records it hands out each
tick and decision (`loop_records`), and what consumes them outside the tick: the metrics recorder,
the safety monitor, the video and the rerun recording."""
