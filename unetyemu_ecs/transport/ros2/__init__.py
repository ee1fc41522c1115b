"""ROS 2 without a bridge node (docs/architecture.md §6): the simulator is a ROS 2 node itself.

Backends: ``rclpy`` (:mod:`.rclpy_backend`) when a sourced ROS 2 Jazzy is there; otherwise ``dds``
(:mod:`.dds_backend`), which speaks the ROS 2 wire protocol over pip ``cyclonedds`` (topic
``rt/<name>``, type ``<pkg>::msg::dds_::<Msg>_`` from rosbags' Jazzy definitions, XCDR1).
:mod:`.bridge` chooses one; :mod:`.inbound` turns command topics into simulation commands.
"""
