"""A ROS 2 peer made of cyclonedds + rosbags only (no project code): subscribe, decode, report.

Usage: python3 listen.py SECONDS TOPIC=TYPE [TOPIC=TYPE ...]
Listens for at most SECONDS, and stops earlier once data has flowed and then stopped for 1.5 s
(the publisher is gone). Prints one JSON object: per topic the number of samples, the CDR of the last one (hex) and the
data representations that the matched writers announced (from DDS discovery), and the
ros_discovery_info samples and writers (their USER_DATA).
"""

from __future__ import annotations

import json
import os
import sys
import time

from cyclonedds.core import Policy
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import make_idl_struct
from cyclonedds.idl import types as t
from cyclonedds.qos import Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.base import Nodetype

CONFIG = """<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface name="lo"/></Interfaces>
<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>
<MaxAutoParticipantIndex>100</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>"""

# the DDS domain the simulator under test uses: ROS_DOMAIN_ID, as the simulator reads it (tests/conftest.py
# gives each pytest-xdist worker a domain of its own)
DOMAIN = int(os.environ.get("ROS_DOMAIN_ID", "").strip() or 0)

TS = get_typestore(Stores.ROS2_JAZZY)
BASE = {"bool": bool, "byte": t.uint8, "char": t.uint8, "int8": t.int8, "uint8": t.uint8, "int16": t.int16,
        "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32, "int64": t.int64, "uint64": t.uint64,
        "float32": t.float32, "float64": t.float64, "string": str}
TYPES: dict[str, type] = {}


def idl(name: str) -> type:
    if name not in TYPES:
        pkg, _, msg = name.split("/")
        fields = {f: field(k, d) for f, (k, d) in TS.fielddefs[name][1]} or {"structure_needs_at_least_one_member": t.uint8}
        TYPES[name] = make_idl_struct(f"{msg}_", f"{pkg}::msg::dds_::{msg}_", fields)
    return TYPES[name]


def field(kind, detail):
    if kind == Nodetype.BASE:
        return t.bounded_str[detail[1]] if detail[0] == "string" and detail[1] else BASE[detail[0]]
    if kind == Nodetype.NAME:
        return idl(detail)
    if kind == Nodetype.ARRAY:
        return t.array[field(*detail[0]), detail[1]]
    return t.sequence[field(*detail[0])]


def qos_for(topic: str) -> Qos:
    durable = topic == "/tf_static"
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)),
               Policy.Durability.TransientLocal if durable else Policy.Durability.Volatile,
               Policy.History.KeepLast(1 if durable else 100))


def main() -> None:
    seconds = float(sys.argv[1])
    wanted = dict(arg.split("=", 1) for arg in sys.argv[2:])
    _domain = Domain(DOMAIN, CONFIG)  # noqa: F841  (keeps the configuration alive)
    dp = DomainParticipant(DOMAIN)
    readers = {}
    for topic, type_name in wanted.items():
        readers[topic] = DataReader(dp, Topic(dp, "rt" + topic, idl(type_name)), qos=qos_for(topic))
    graph_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.TransientLocal,
                    Policy.History.KeepLast(1))
    graph = DataReader(dp, Topic(dp, "ros_discovery_info", idl("rmw_dds_common/msg/ParticipantEntitiesInfo")),
                       qos=graph_qos)
    graph_info: list[str] = []
    graph_writers: dict[str, str] = {}         # the ros_discovery_info writers matched: gid -> USER_DATA
    print("ready", flush=True)
    counts = {topic: 0 for topic in wanted}
    last: dict[str, bytes] = {}
    representation: dict[str, list] = {}
    end = time.monotonic() + seconds
    last_rx = None
    while time.monotonic() < end and not (last_rx and time.monotonic() - last_rx > 1.5):
        for topic, reader in readers.items():
            for sample in reader.take(N=100):
                if not hasattr(sample, "serialize"):        # an invalid sample (a writer went away)
                    continue
                counts[topic] += 1
                last[topic] = sample.serialize(use_version_2=False)
                last_rx = time.monotonic()
            # what the matched writers announced in discovery
            for handle in reader.get_matched_publications():
                pub = reader.get_matched_publication_data(handle)
                rep = pub.qos[Policy.DataRepresentation]
                user = pub.qos[Policy.Userdata]
                representation[topic] = {"type": pub.type_name, "xcdr1": bool(rep and rep.use_cdrv0_representation),
                                         "xcdr2": bool(rep and rep.use_xcdrv2_representation),
                                         "user_data": user.data.decode() if user else "",
                                         "gid": bytes(pub.key.bytes).hex()}
        graph_info += [g.serialize(use_version_2=False).hex() for g in graph.take(N=10) if hasattr(g, "serialize")]
        for handle in graph.get_matched_publications():
            pub = graph.get_matched_publication_data(handle)
            user = pub.qos[Policy.Userdata]
            graph_writers[bytes(pub.key.bytes).hex()] = user.data.decode() if user else ""
        time.sleep(0.01)
    print(json.dumps({"counts": counts, "last": {k: v.hex() for k, v in last.items()},
                      "writers": representation, "graph": graph_info,
                      "graph_writers": graph_writers}), flush=True)


if __name__ == "__main__":
    main()
