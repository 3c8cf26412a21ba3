"""Simulated CANopen devices for everyone without the robot: CiA 402 drives and CiA 404 sensors on the
robot's MuJoCo model."""
