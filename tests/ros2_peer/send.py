"""A ROS 2 peer (cyclonedds + rosbags only, no project code) that sends commands and listens to the
simulator's /rosout and mission status.

Usage: python3 send.py SECONDS COMMANDS_JSON  (listens at most SECONDS, or until /clock stops)
COMMANDS_JSON: a list of [topic, type, fields] sent in order, 0.2 s apart, once the simulator's
/clock is seen (fields are the message's fields as JSON: {"data": ...} or {"linear": {...}, ...}).
Prints one JSON object: the /rosout texts and the mission status texts received.
"""

from __future__ import annotations

import json
import sys
import time

from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from listen import CONFIG, DOMAIN, idl, qos_for  # noqa: E402  (same folder)


def build(type_name: str, fields: dict):
    cls = idl(type_name)
    from listen import TS
    kw = {}
    for name, (kind, detail) in TS.fielddefs[type_name][1]:
        if name in fields:
            v = fields[name]
            kw[name] = build(detail, v) if isinstance(v, dict) else v
        else:
            kw[name] = build(detail, {}) if isinstance(detail, str) else ([] if kind == 4 else
                                                                          "" if detail[0] == "string" else 0)
    return cls(**kw)


def main() -> None:
    seconds, commands = float(sys.argv[1]), json.loads(sys.argv[2])
    _domain = Domain(DOMAIN, CONFIG)  # noqa: F841  (keeps the configuration alive)
    dp = DomainParticipant(DOMAIN)
    clock = DataReader(dp, Topic(dp, "rt/clock", idl("rosgraph_msgs/msg/Clock")), qos=qos_for("/clock"))
    rosout = DataReader(dp, Topic(dp, "rt/rosout", idl("rcl_interfaces/msg/Log")), qos=qos_for("/rosout"))
    status_topics = sorted({c[0].rsplit("/", 1)[0] + "/mission/status" for c in commands if c[0].endswith("/mission")})
    statuses = {t: DataReader(dp, Topic(dp, "rt" + t, idl("std_msgs/msg/String")), qos=qos_for(t)) for t in status_topics}
    writers = {}
    for topic, type_name, _ in commands:
        if topic not in writers:
            writers[topic] = DataWriter(dp, Topic(dp, "rt" + topic, idl(type_name)), qos=qos_for(topic))
    print("ready", flush=True)
    end = time.monotonic() + seconds
    while not clock.take(N=10) and time.monotonic() < end:
        time.sleep(0.05)
    while time.monotonic() < end and not all(w.get_matched_subscriptions() for w in writers.values()):
        time.sleep(0.05)                  # every writer matched the simulator's reader (discovery has no fixed time)
    time.sleep(0.2)
    logs, seen_status = [], []
    for topic, type_name, fields in commands:
        writers[topic].write(build(type_name, fields))
        time.sleep(0.2)
    last_clock = time.monotonic()
    while time.monotonic() < end and time.monotonic() - last_clock < 1.5:     # until the simulator is gone
        if [c for c in clock.take(N=100) if hasattr(c, "clock")]:
            last_clock = time.monotonic()
        logs += [s.msg for s in rosout.take(N=50) if hasattr(s, "msg")]
        for reader in statuses.values():
            seen_status += [s.data for s in reader.take(N=50) if hasattr(s, "data")]
        time.sleep(0.05)
    print(json.dumps({"rosout": logs, "status": seen_status}), flush=True)


if __name__ == "__main__":
    main()
