"""/tf's own CDR writer gives, byte for byte, what rosbags' generic serializer gives for every TFMessage."""

from __future__ import annotations

import numpy as np
import pytest

from unetyemu_ecs.sensors.messages import deserialize, msg_type, serialize, stamp, tf_message_cdr, typestore
from unetyemu_ecs.sensors.tf import tf_message


def generic(msg) -> bytes:
    return bytes(typestore().serialize_cdr(msg, msg.__msgtype__))


@pytest.mark.parametrize("n", [0, 1, 2, 7, 60])
def test_a_tf_message_of_n_vehicles_is_written_exactly_as_rosbags_writes_it(n):
    rng = np.random.default_rng(n)
    # names of every length mod 4 and 8 (the padding before each string and before the doubles), one non-ASCII
    frames = tuple((f"{'v' * (i % 9)}{i}/odom", f"{'w' * (i % 5)}{i}/base_link" if i != 3 else "drône/base_link")
                   for i in range(n))
    xyz = rng.normal(0.0, 100.0, (n, 3))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    for time_s in (0.0, 1.25, 12345.678901234):
        msg = tf_message(time_s, frames, xyz, q)
        data = serialize(msg)
        assert data == generic(msg) == tf_message_cdr(msg)
        back = deserialize(data, "tf2_msgs/msg/TFMessage")
        assert [(t.header.frame_id, t.child_frame_id) for t in back.transforms] == list(frames)
        if n:
            got = np.array([[t.transform.translation.x, t.transform.translation.y, t.transform.translation.z]
                            for t in back.transforms])
            assert np.array_equal(got, xyz)                     # float64 on the wire: exact


def test_a_tf_message_holds_the_same_values_as_one_built_field_by_field():
    xyz, q = np.array([[1.5, -2.0, 3.25]], dtype=np.float32), np.array([[0.0, 0.0, 0.6, 0.8]])
    msg = tf_message(2.5, (("map", "d1/odom"),), xyz, q)
    T, Transform = msg_type("geometry_msgs/msg/TransformStamped"), msg_type("geometry_msgs/msg/Transform")
    Vector3, Quaternion = msg_type("geometry_msgs/msg/Vector3"), msg_type("geometry_msgs/msg/Quaternion")
    by_hand = msg_type("tf2_msgs/msg/TFMessage")(transforms=[T(
        header=msg_type("std_msgs/msg/Header")(stamp=stamp(2.5), frame_id="map"), child_frame_id="d1/odom",
        transform=Transform(translation=Vector3(x=float(xyz[0, 0]), y=float(xyz[0, 1]), z=float(xyz[0, 2])),
                            rotation=Quaternion(x=0.0, y=0.0, z=0.6, w=0.8)))])
    assert msg == by_hand and serialize(msg) == generic(by_hand)
