"""Reading a recorded session (a ROS bag, rehabkit's or another producer's) and replaying it as a scenario."""
