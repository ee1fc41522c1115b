"""cyclonedds IDL types generated from the ROS 2 Jazzy message definitions of ``rosbags``.

``idl_type("sensor_msgs/msg/Imu")`` is the ``sensor_msgs::msg::dds_::Imu_`` struct ROS 2 puts on
the wire; :func:`to_idl` converts a rosbags message object into it. Serialised, both are byte for
byte what ``rosbags`` gives (checked in the tests). Readers use these types; writers normally send
rosbags' own serialisation (:mod:`.dds_backend`), and :func:`to_idl` is their fallback (it walks
large arrays as Python lists: ~48 ms for a 640x480 image).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from ...sensors.messages import typestore


def _base_types() -> dict[str, Any]:
    import cyclonedds.idl.types as t

    return {"bool": bool, "byte": t.uint8, "char": t.uint8, "int8": t.int8, "uint8": t.uint8, "int16": t.int16,
            "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32, "int64": t.int64, "uint64": t.uint64,
            "float32": t.float32, "float64": t.float64, "string": str}


@cache
def idl_type(name: str) -> type:
    """The cyclonedds struct for ROS 2 type ``name`` (``pkg/msg/Name``), DDS name ``pkg::msg::dds_::Name_``."""
    from cyclonedds.idl import make_idl_struct

    pkg, _, msg = name.split("/")
    fields = {fname: _field_type(ntype, detail) for fname, (ntype, detail) in typestore().fielddefs[name][1]}
    if not fields:                                    # ROS 2 pads empty messages with one uint8
        fields["structure_needs_at_least_one_member"] = _base_types()["uint8"]
    return make_idl_struct(f"{msg}_", f"{pkg}::msg::dds_::{msg}_", fields)


def _field_type(ntype: Any, detail: Any) -> Any:
    from cyclonedds.idl import types as t
    from rosbags.typesys.base import Nodetype

    if ntype == Nodetype.BASE:
        if detail[0] == "string" and detail[1]:
            return t.bounded_str[detail[1]]              # string<N>: same CDR, a different type object
        return _base_types()[detail[0]]
    if ntype == Nodetype.NAME:
        return idl_type(detail)
    if ntype == Nodetype.ARRAY:
        return t.array[_field_type(*detail[0]), detail[1]]
    if ntype == Nodetype.SEQUENCE:
        return t.sequence[_field_type(*detail[0])]
    raise ValueError(f"unsupported ROS 2 field kind {ntype!r}")


def to_idl(msg: Any) -> Any:
    """The cyclonedds struct instance holding the same values as rosbags message ``msg``."""
    name = msg.__msgtype__
    values = {}
    for fname, _ in typestore().fielddefs[name][1]:
        v = getattr(msg, fname)
        if hasattr(v, "__msgtype__"):
            v = to_idl(v)
        elif isinstance(v, list):
            v = [to_idl(x) if hasattr(x, "__msgtype__") else x for x in v]
        elif isinstance(v, np.ndarray):
            v = v.tolist()
        values[fname] = v
    if not values:
        values["structure_needs_at_least_one_member"] = 0
    return idl_type(name)(**values)


__all__ = ["idl_type", "to_idl"]
