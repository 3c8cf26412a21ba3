"""The ROS layer: runs as ROS 2 bags (MCAP with ROS 2 messages), for Foxglove, PlotJuggler and a lab's ROS tools."""
