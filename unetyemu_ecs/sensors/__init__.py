"""Sensor plugins: LiDAR, RGB and depth cameras, IMU, GPS, battery, odometry and the TF tree.

Each produces ROS 2 Jazzy messages (:mod:`.messages`) on the sim clock; see :mod:`.base` for what
every sensor shares and how to write one.
"""
