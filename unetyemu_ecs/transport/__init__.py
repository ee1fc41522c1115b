"""Edges of the simulator: command bus, ROS 2 bridge, MAVLink endpoint (threads talk to the loop via queues)."""
