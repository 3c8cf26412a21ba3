"""State estimation: Kalman filtering of sensor signals, rigid-body motion from accelerometers."""
