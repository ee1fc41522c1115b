"""ROS 2 over the wire without ROS installed: DDS types from rosbags' Jazzy definitions and publishers.

Backends (DESIGN.md §6): ``dds`` speaks the ROS 2 wire protocol itself over pip ``cyclonedds``
(topic ``rt/<name>``, type ``<pkg>::msg::dds_::<Msg>_``, XCDR1). The ``rclpy`` backend and the
inbound command topics are not built yet.
"""
