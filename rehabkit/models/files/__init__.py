"""Robots from model files: MJCF and URDF imported, ROS description packages made loadable."""
