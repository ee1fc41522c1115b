"""ROS 2 parameter services of the ``dds`` backend's node, as rmw_cyclonedds_cpp serves them.

A ROS 2 service over DDS is two topics: requests on ``rq/<node>/<service>Request`` (type
``rcl_interfaces::srv::dds_::<Srv>_Request_``) and replies on ``rr/<node>/<service>Reply``
(``..._Response_``), QoS Reliable / Volatile / KeepLast(10). rmw_cyclonedds_cpp puts a 16-byte
header in front of each payload, right after the CDR encapsulation (``cdds_request_header_t``: the
client's 64-bit id, then the request's int64 sequence number); a reply echoes the request's header
and the client picks its own replies by it. As rmw_cyclonedds, the service's endpoints carry
``serviceid=...;`` in USER_DATA (a client takes the service as available once it has matched a
request reader and a reply writer with the same id), and a reply waits (at most 0.5 s) until the
reply writer has matched the reader of the client named by ``clientid=`` on its request writer. Served here: ``list_parameters``, ``get_parameters``,
``describe_parameters``, ``get_parameter_types``, ``set_parameters`` and
``set_parameters_atomically`` (which refuse: every parameter is read-only).

Limitation: rmw_fastrtps_cpp does not use that header; it identifies a request by the RTPS sample
identity (inline QoS of the request sample), which pip cyclonedds can neither read nor write.
``ros2 param`` works against this node with rmw_cyclonedds_cpp; with rmw_fastrtps_cpp the services
are listed but calls time out (the ``rclpy`` backend serves them for every RMW).
"""

from __future__ import annotations

import time
from functools import cache
from typing import Any

from ...sensors.messages import msg_type, stamp
from .dds_backend import MAX_BLOCKING_MS, NODE_NAME, DdsPublisher, _write_raw

HEADER_BYTES = 16                # cdds_request_header_t: uint64 client id + int64 sequence number
ENCAPSULATION_BYTES = 4
REPLY_MATCH_WAIT_S = 0.5         # how long a reply waits for the client's reply reader to match

# Jazzy rcl_interfaces service definitions (fields only; constants do not travel)
SERVICES = {
    "ListParameters": ("string[] prefixes\nuint64 depth", "rcl_interfaces/msg/ListParametersResult result"),
    "GetParameters": ("string[] names", "rcl_interfaces/msg/ParameterValue[] values"),
    "DescribeParameters": ("string[] names", "rcl_interfaces/msg/ParameterDescriptor[] descriptors"),
    "GetParameterTypes": ("string[] names", "uint8[] types"),
    "SetParameters": ("rcl_interfaces/msg/Parameter[] parameters", "rcl_interfaces/msg/SetParametersResult[] results"),
    "SetParametersAtomically": ("rcl_interfaces/msg/Parameter[] parameters",
                                "rcl_interfaces/msg/SetParametersResult result"),
}
SERVICE_NAMES = {"list_parameters": "ListParameters", "get_parameters": "GetParameters",
                 "describe_parameters": "DescribeParameters", "get_parameter_types": "GetParameterTypes",
                 "set_parameters": "SetParameters", "set_parameters_atomically": "SetParametersAtomically"}

# rcl_interfaces/msg/ParameterType
NOT_SET, BOOL, INTEGER, DOUBLE, STRING = 0, 1, 2, 3, 4


@cache
def service_typestore() -> Any:
    """A Jazzy typestore with the ``rcl_interfaces/srv/*_Request`` / ``_Response`` types added."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    for srv, definitions in SERVICES.items():
        for part, text in zip(("Request", "Response"), definitions):
            # rosbags files a non-msg name under <pkg>/srv/msg/...: parse, then register under the ROS name
            (parsed,) = get_types_from_msg(text, f"rcl_interfaces/msg/{srv}_{part}").values()
            store.register({f"rcl_interfaces/srv/{srv}_{part}": parsed})
    return store


@cache
def wire_type(type_name: str) -> type:
    """The cyclonedds struct of a service payload as it travels: header fields, then the message's."""
    from cyclonedds.idl import make_idl_struct
    from cyclonedds.idl import types as t

    from .dds_types import _field_type

    pkg, _, name = type_name.split("/")
    fields: dict[str, Any] = {"client_id": t.uint64, "sequence_number": t.int64}
    for fname, (ntype, detail) in service_typestore().fielddefs[type_name][1]:
        fields[fname] = _field_type(ntype, detail)
    return make_idl_struct(f"{name}_", f"{pkg}::srv::dds_::{name}_", fields)


def parameter_value(value: bool | int | float | str) -> Any:
    """``rcl_interfaces/msg/ParameterValue`` holding ``value``."""
    import numpy as np

    Value = msg_type("rcl_interfaces/msg/ParameterValue")
    kw: dict[str, Any] = {"type": NOT_SET, "bool_value": False, "integer_value": 0, "double_value": 0.0,
                          "string_value": "", "byte_array_value": np.zeros(0, np.uint8),
                          "bool_array_value": np.zeros(0, bool), "integer_array_value": np.zeros(0, np.int64),
                          "double_array_value": np.zeros(0, np.float64), "string_array_value": []}
    if isinstance(value, bool):
        kw.update(type=BOOL, bool_value=value)
    elif isinstance(value, int):
        kw.update(type=INTEGER, integer_value=value)
    elif isinstance(value, float):
        kw.update(type=DOUBLE, double_value=value)
    elif isinstance(value, str):
        kw.update(type=STRING, string_value=value)
    return Value(**kw)


class ParameterServer:
    """The read-only parameters of node ``/unetyemu_sim`` over DDS (see the module docstring).

    ``parameters`` maps a name to a bool, int, float or str. Requests are handled on the command
    listener's thread (:attr:`services` gives it the readers and their handlers); ``/parameter_events``
    announces the parameters once, at start, as rcl does when a node declares them.
    """

    def __init__(self, publisher: DdsPublisher, parameters: dict[str, bool | int | float | str]) -> None:
        from cyclonedds.core import Policy
        from cyclonedds.pub import DataWriter
        from cyclonedds.qos import Qos
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from cyclonedds.util import duration

        self.parameters = dict(parameters)
        self._publisher = publisher
        dp = publisher.participant
        store = service_typestore()
        self.services: list[tuple[Any, Any]] = []
        self._writers: dict[str, Any] = {}
        reader_of: dict[str, Any] = {}
        for service, srv in SERVICE_NAMES.items():
            for suffix, prefix, part in (("Request", "rq", "Request"), ("Reply", "rr", "Response")):
                type_name = f"rcl_interfaces/srv/{srv}_{part}"
                qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=MAX_BLOCKING_MS)),
                          Policy.Durability.Volatile, Policy.History.KeepLast(10),
                          Policy.DataRepresentation(use_cdrv0_representation=True),
                          Policy.Userdata(f"serviceid={self._service_id(dp, service)};"
                                          f"typehash={store.hash_rihs01(type_name)};".encode()))
                topic = Topic(dp, f"{prefix}/{NODE_NAME}/{service}{suffix}", wire_type(type_name), qos=qos)
                if prefix == "rq":
                    reader = reader_of[service] = DataReader(dp, topic, qos=qos)
                    publisher.reader_gids.append(reader.guid.bytes)
                    self.services.append((reader, self._handler(service, srv, reader_of)))
                else:
                    writer = self._writers[service] = DataWriter(dp, topic, qos=qos)
                    publisher.writer_gids.append(writer.guid.bytes)
        publisher.announce()
        Parameter = msg_type("rcl_interfaces/msg/Parameter")
        publisher.publish("/parameter_events", msg_type("rcl_interfaces/msg/ParameterEvent")(
            stamp=stamp(0.0), node=f"/{NODE_NAME}",
            new_parameters=[Parameter(name=k, value=parameter_value(v)) for k, v in sorted(self.parameters.items())],
            changed_parameters=[], deleted_parameters=[]))

    def _handler(self, service: str, srv: str, reader_of: dict[str, Any]) -> Any:
        store = service_typestore()

        def handle(cdr: bytes, info: Any) -> None:       # command listener thread
            if len(cdr) < ENCAPSULATION_BYTES + HEADER_BYTES:
                raise ValueError(f"{service} request of {len(cdr)} bytes has no request header")
            header = cdr[ENCAPSULATION_BYTES:ENCAPSULATION_BYTES + HEADER_BYTES]
            body = cdr[:ENCAPSULATION_BYTES] + cdr[ENCAPSULATION_BYTES + HEADER_BYTES:]
            request = store.deserialize_cdr(body, f"rcl_interfaces/srv/{srv}_Request")
            response = getattr(self, f"_{service}")(request)
            out = bytes(store.serialize_cdr(response, response.__msgtype__))
            writer = self._writers[service]
            client = self._client_id(reader_of[service], info.publication_handle)
            deadline = time.monotonic() + REPLY_MATCH_WAIT_S
            while not self._reply_reader_matched(writer, client) and time.monotonic() < deadline:
                time.sleep(0.01)                         # the client's reply reader is still being discovered
            _write_raw(writer, out[:ENCAPSULATION_BYTES] + header + out[ENCAPSULATION_BYTES:])
        return handle

    @staticmethod
    def _service_id(participant: Any, service: str) -> str:
        """A unique id for one service's reader/writer pair, written as rmw_cyclonedds writes them."""
        raw = bytes(participant.guid.bytes[:12]) + (list(SERVICE_NAMES).index(service) + 1).to_bytes(4, "big")
        return ".".join(f"{b:x}" for b in raw)

    @staticmethod
    def _user_data_key(qos: Any, key: str) -> str | None:
        from cyclonedds.core import Policy

        user = qos[Policy.Userdata] if qos is not None else None
        for item in (user.data.decode(errors="replace") if user else "").split(";"):
            name, _, value = item.partition("=")
            if name == key:
                return value
        return None

    def _client_id(self, reader: Any, publication_handle: int) -> str | None:
        """The ``clientid`` an rmw_cyclonedds client puts in its request writer's USER_DATA (or None)."""
        try:
            return self._user_data_key(reader.get_matched_publication_data(publication_handle).qos, "clientid")
        except Exception:                               # the client's writer is gone already
            return None

    def _reply_reader_matched(self, writer: Any, client: str | None) -> bool:
        """Whether the reply writer has matched the requesting client's reply reader (as rmw_cyclonedds
        servers wait for it, 100 ms there); any reader for a client without a ``clientid``."""
        handles = writer.get_matched_subscriptions()
        if client is None:
            return bool(handles)
        for handle in handles:
            try:
                if self._user_data_key(writer.get_matched_subscription_data(handle).qos, "clientid") == client:
                    return True
            except Exception:
                continue
        return False

    def _response(self, srv: str, **fields: Any) -> Any:
        return service_typestore().types[f"rcl_interfaces/srv/{srv}_Response"](**fields)

    def _list_parameters(self, request: Any) -> Any:
        prefixes = list(request.prefixes)
        depth = int(request.depth)                       # 0: recursive (DEPTH_RECURSIVE)
        names = []
        for name in sorted(self.parameters):
            if prefixes and not any(name == p or name.startswith(p + ".") for p in prefixes):
                continue
            if depth and name.count(".") >= depth:
                continue
            names.append(name)
        found = sorted({n.rsplit(".", 1)[0] for n in names if "." in n})
        result = msg_type("rcl_interfaces/msg/ListParametersResult")(names=names, prefixes=found)
        return self._response("ListParameters", result=result)

    def _get_parameters(self, request: Any) -> Any:
        return self._response("GetParameters", values=[
            parameter_value(self.parameters[n]) if n in self.parameters else parameter_value(None)
            for n in request.names])

    def _describe_parameters(self, request: Any) -> Any:
        Descriptor = msg_type("rcl_interfaces/msg/ParameterDescriptor")
        out = []
        for name in request.names:
            known = name in self.parameters
            out.append(Descriptor(
                name=name, type=parameter_value(self.parameters[name]).type if known else NOT_SET,
                description="set by the world file (read-only)" if known else "", additional_constraints="",
                read_only=known, dynamic_typing=False, floating_point_range=[], integer_range=[]))
        return self._response("DescribeParameters", descriptors=out)

    def _get_parameter_types(self, request: Any) -> Any:
        import numpy as np

        types = [parameter_value(self.parameters[n]).type if n in self.parameters else NOT_SET for n in request.names]
        return self._response("GetParameterTypes", types=np.array(types, dtype=np.uint8))

    def _refusal(self, name: str) -> Any:
        reason = (f"parameter {name!r} is read-only" if name in self.parameters
                  else f"parameter {name!r} is not declared")
        return msg_type("rcl_interfaces/msg/SetParametersResult")(successful=False, reason=reason)

    def _set_parameters(self, request: Any) -> Any:
        return self._response("SetParameters", results=[self._refusal(p.name) for p in request.parameters])

    def _set_parameters_atomically(self, request: Any) -> Any:
        names = [p.name for p in request.parameters]
        return self._response("SetParametersAtomically", result=self._refusal(names[0] if names else ""))


__all__ = ["HEADER_BYTES", "SERVICE_NAMES", "ParameterServer", "parameter_value", "service_typestore", "wire_type"]
