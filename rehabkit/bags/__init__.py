"""Reading a session recorded on a robot from its ROS bag (below the layers: the ROS layer replays it, a patient
plugin plays a recorded wrench back through :mod:`rehabkit.recordings`)."""
