"""A ROS 2 peer (cyclonedds + rosbags only, no project code) for the robustness tests.

Usage:
  python3 probe.py write SECONDS PAYLOADS_JSON_FILE
      Wait for the simulator's /clock, then write each [topic, type, hex] of the file as one raw
      sample (the bytes as they are: garbage included), 2 ms apart, each writer first matched;
      a [topic, type, hex, "pause"] entry waits 0.5 s before it. Prints {"written": n, "refused": m}
      (cyclonedds refuses to write a sample shorter than a CDR header).
  python3 probe.py late SECONDS TOPIC=TYPE [...]
      Join late: TransientLocal, Reliable, KeepLast(1000) readers; print every sample received
      within SECONDS (hex CDR per topic) as one JSON object.
  python3 probe.py params SECONDS
      Act as an rmw_cyclonedds_cpp client of /unetyemu_sim's parameter services (16-byte request
      header: client id, sequence number; clientid= in USER_DATA; availability by serviceid=) and
      print the decoded replies as JSON.
"""

from __future__ import annotations

import json
import sys
import time

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.core import InstanceState, Policy, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import make_idl_struct
from cyclonedds.idl import types as t
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
from rosbags.typesys import get_types_from_msg

from listen import CONFIG, DOMAIN, TS, field, idl, qos_for  # noqa: E402  (same folder)


def raw_write(writer: DataWriter, data: bytes) -> bool:
    """Write ``data`` as one sample; False when cyclonedds refuses it (shorter than a CDR header)."""
    data += b"\0" * ((-len(data)) % 4)
    return ddspy_write(writer._ref, data) >= 0


def raw_take(reader: DataReader) -> list[bytes]:
    ret = ddspy_take(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, 100)
    return [] if isinstance(ret, int) else [bytes(d) for d, info in ret if info.valid_data]


def wait_for_clock(dp: DomainParticipant, seconds: float) -> None:
    clock = DataReader(dp, Topic(dp, "rt/clock", idl("rosgraph_msgs/msg/Clock")), qos=qos_for("/clock"))
    end = time.monotonic() + seconds
    while time.monotonic() < end and not clock.take(N=10):
        time.sleep(0.02)


def write(seconds: float, path: str) -> None:
    payloads = json.load(open(path))
    dp = DomainParticipant(DOMAIN)
    print("ready", flush=True)
    wait_for_clock(dp, seconds)
    writers: dict[str, DataWriter] = {}
    for topic, type_name, *_ in payloads:
        if topic not in writers:
            qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
                      Policy.History.KeepAll, Policy.DataRepresentation(use_cdrv0_representation=True))
            writers[topic] = DataWriter(dp, Topic(dp, "rt" + topic, idl(type_name)), qos=qos)
    end = time.monotonic() + seconds
    while time.monotonic() < end and not all(w.get_matched_subscriptions() for w in writers.values()):
        time.sleep(0.02)
    time.sleep(0.3)
    written = refused = 0
    for topic, _, data, *pause in payloads:
        if pause:
            time.sleep(0.5)
        if raw_write(writers[topic], bytes.fromhex(data)):
            written += 1
        else:
            refused += 1
        time.sleep(0.002)
    time.sleep(1.0)                                   # let reliable delivery finish before the writers go
    print(json.dumps({"written": written, "refused": refused}), flush=True)


def late(seconds: float, wanted: dict[str, str]) -> None:
    dp = DomainParticipant(DOMAIN)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
              Policy.History.KeepLast(1000))
    readers = {topic: DataReader(dp, Topic(dp, "rt" + topic, idl(ty)), qos=qos) for topic, ty in wanted.items()}
    got: dict[str, list[str]] = {topic: [] for topic in wanted}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for topic, reader in readers.items():
            got[topic] += [cdr.hex() for cdr in raw_take(reader)]
        if all(got.values()) and time.monotonic() > end - seconds + 2.0:
            break
        time.sleep(0.02)
    print(json.dumps(got), flush=True)


SERVICES = {
    "list_parameters": ("ListParameters", "string[] prefixes\nuint64 depth",
                        "rcl_interfaces/msg/ListParametersResult result"),
    "get_parameters": ("GetParameters", "string[] names", "rcl_interfaces/msg/ParameterValue[] values"),
    "describe_parameters": ("DescribeParameters", "string[] names",
                            "rcl_interfaces/msg/ParameterDescriptor[] descriptors"),
    "get_parameter_types": ("GetParameterTypes", "string[] names", "uint8[] types"),
    "set_parameters": ("SetParameters", "rcl_interfaces/msg/Parameter[] parameters",
                       "rcl_interfaces/msg/SetParametersResult[] results"),
}
CLIENT_ID = 0x1234_5678_9ABC_DEF0


def params(seconds: float) -> None:
    import numpy as np

    dp = DomainParticipant(DOMAIN)
    for _, (srv, request, response) in SERVICES.items():
        for part, text in (("Request", request), ("Response", response)):
            (parsed,) = get_types_from_msg(text, f"rcl_interfaces/msg/{srv}_{part}").values()
            TS.register({f"rcl_interfaces/srv/{srv}_{part}": parsed})
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile,
              Policy.History.KeepLast(10), Policy.DataRepresentation(use_cdrv0_representation=True),
              Policy.Userdata(b"clientid=de.ad.be.ef.0.0.0.0.0.0.0.0.0.0.0.1;"))   # as rmw_cyclonedds clients
    ends = {}
    for service, (srv, _, _) in SERVICES.items():
        def wire(part: str) -> type:
            fields = {"client_id": t.uint64, "sequence_number": t.int64}
            fields |= {f: field(k, d) for f, (k, d) in TS.fielddefs[f"rcl_interfaces/srv/{srv}_{part}"][1]}
            return make_idl_struct(f"{srv}_{part}_", f"rcl_interfaces::srv::dds_::{srv}_{part}_", fields)
        writer = DataWriter(dp, Topic(dp, f"rq/unetyemu_sim/{service}Request", wire("Request")), qos=qos)
        reader = DataReader(dp, Topic(dp, f"rr/unetyemu_sim/{service}Reply", wire("Response")), qos=qos)
        ends[service] = (writer, reader)
    Parameter = TS.types["rcl_interfaces/msg/Parameter"]
    Value = TS.types["rcl_interfaces/msg/ParameterValue"]
    empty = dict(bool_value=False, integer_value=0, double_value=0.0, string_value="",
                 byte_array_value=np.zeros(0, np.uint8), bool_array_value=np.zeros(0, bool),
                 integer_array_value=np.zeros(0, np.int64), double_array_value=np.zeros(0, np.float64),
                 string_array_value=[])
    names = ["use_sim_time", "world.name", "world.seed", "no.such"]
    requests = {
        "list_parameters": {"prefixes": [], "depth": 0},
        "get_parameters": {"names": names},
        "describe_parameters": {"names": names},
        "get_parameter_types": {"names": names},
        "set_parameters": {"parameters": [Parameter(name="world.seed", value=Value(type=2, **empty | {"integer_value": 7}))]},
    }
    end = time.monotonic() + seconds
    while time.monotonic() < end and not all(w.get_matched_subscriptions() and r.get_matched_publications()
                                              for w, r in ends.values()):
        time.sleep(0.02)
    out = {"service_available": {}}
    for service, (writer, reader) in ends.items():
        # rmw_service_server_is_available: a matched request reader and reply writer with the same serviceid
        def ids(endpoint, handles, data):
            found = set()
            for h in handles:
                user = data(h).qos[Policy.Userdata]
                found |= {kv[10:] for kv in (user.data.decode() if user else "").split(";") if kv.startswith("serviceid=")}
            return found
        requests_ids = ids(writer, writer.get_matched_subscriptions(), writer.get_matched_subscription_data)
        replies_ids = ids(reader, reader.get_matched_publications(), reader.get_matched_publication_data)
        out["service_available"][service] = bool(requests_ids & replies_ids)
    for seq, (service, fields) in enumerate(requests.items(), start=1):
        srv = SERVICES[service][0]
        writer, reader = ends[service]
        cdr = bytes(TS.serialize_cdr(TS.types[f"rcl_interfaces/srv/{srv}_Request"](**fields),
                                     f"rcl_interfaces/srv/{srv}_Request"))
        header = CLIENT_ID.to_bytes(8, "little") + seq.to_bytes(8, "little", signed=True)
        raw_write(writer, cdr[:4] + header + cdr[4:])
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and service not in out:
            for reply in raw_take(reader):
                client, number = int.from_bytes(reply[4:12], "little"), int.from_bytes(reply[12:20], "little")
                if (client, number) == (CLIENT_ID, seq):
                    out[service] = to_json(TS.deserialize_cdr(reply[:4] + reply[20:], f"rcl_interfaces/srv/{srv}_Response"))
            time.sleep(0.01)
    print(json.dumps(out), flush=True)


def to_json(msg):
    if hasattr(msg, "__msgtype__"):
        return {k: to_json(getattr(msg, k)) for k in msg.__dataclass_fields__}
    if isinstance(msg, list):
        return [to_json(v) for v in msg]
    if hasattr(msg, "tolist"):
        return msg.tolist()
    return msg


def main() -> None:
    _domain = Domain(DOMAIN, CONFIG)  # noqa: F841  (keeps the configuration alive)
    mode, seconds = sys.argv[1], float(sys.argv[2])
    if mode == "write":
        write(seconds, sys.argv[3])
    elif mode == "late":
        late(seconds, dict(arg.split("=", 1) for arg in sys.argv[3:]))
    elif mode == "params":
        params(seconds)
    else:
        raise SystemExit(f"unknown mode {mode!r}")


if __name__ == "__main__":
    main()
