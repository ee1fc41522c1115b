"""The world-file component ``mavlink``: a drone's MAVLink endpoint (ports, ids, streams, signing).

Ports follow PX4 SITL (``px4-rc.mavlink``) for instance ``i``: the API/offboard link binds
``api_local_base + i`` and sends to ``api_remote_base + i`` (MAVSDK's ``udpin://:14540``; PX4 uses
``api_remote_base + 9`` for every instance above 9 so it never lands on 14550); the GCS link binds
``gcs_local_base + i`` and sends to ``gcs_remote`` (QGroundControl, MAVProxy). System id ``i + 1``,
component 1 (the autopilot).
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from typing import Annotated, Literal

from ...config.schema import FieldError, Ge, Le, MaxLen, NonEmpty

MAX_INSTANCE = 254                # system id = instance + 1 <= 255
SYSTEM_ID_OFFSET = 1
COMPONENT_ID = 1                  # MAV_COMP_ID_AUTOPILOT1
PORT_LO, PORT_HI = 1024, 65535    # never a privileged port


@dataclass(frozen=True, slots=True, kw_only=True)
class MavlinkSigning:
    """MAVLink 2 signing of one endpoint: the 32-byte secret from a file or an environment variable
    (32 raw bytes, 64 hex digits, or any other text = its SHA-256, like MAVProxy's ``signing setup``).
    ``required``: unsigned or wrongly signed messages are dropped (telemetry keeps flowing)."""

    key_file: Annotated[str, NonEmpty(), MaxLen(4096)] | None = None
    key_env: Annotated[str, NonEmpty(), MaxLen(256)] | None = None
    required: bool = True

    def __post_init__(self) -> None:
        if (self.key_file is None) == (self.key_env is None):
            raise FieldError("key_file", "give exactly one of key_file and key_env")


@dataclass(frozen=True, slots=True, kw_only=True)
class MavlinkEndpoint:
    """A drone's MAVLink endpoint (world-file key ``mavlink``), like PX4 SITL instance ``instance``."""

    instance: Annotated[int, Ge(0), Le(MAX_INSTANCE)]
    bind: Annotated[str, NonEmpty(), MaxLen(64)] = "127.0.0.1"
    api_local_base: Annotated[int, Ge(PORT_LO), Le(PORT_HI)] = 14580
    api_remote_base: Annotated[int, Ge(PORT_LO), Le(PORT_HI)] = 14540
    gcs_local_base: Annotated[int, Ge(PORT_LO), Le(PORT_HI)] = 18570
    gcs_remote: Annotated[int, Ge(PORT_LO), Le(PORT_HI)] = 14550
    streams: Literal["px4", "reduced"] = "px4"
    signing: MavlinkSigning | None = None

    def __post_init__(self) -> None:
        try:
            address = ipaddress.ip_address(self.bind)
        except ValueError:
            raise FieldError("bind", f"must be an IPv4 address such as 127.0.0.1, got {self.bind!r}") from None
        if address.version != 4:
            raise FieldError("bind", f"must be an IPv4 address, got {self.bind!r}")
        for name in ("api_local_base", "api_remote_base", "gcs_local_base"):
            port = getattr(self, name) + min(self.instance, 9 if name == "api_remote_base" else self.instance)
            if port > PORT_HI:
                raise FieldError(name, f"{name} + instance {self.instance} = {port} is beyond port {PORT_HI}")

    @property
    def system_id(self) -> int:
        return self.instance + SYSTEM_ID_OFFSET

    @property
    def api_local_port(self) -> int:
        return self.api_local_base + self.instance

    @property
    def api_remote_port(self) -> int:
        return self.api_remote_base + (self.instance if self.instance <= 9 else 9)

    @property
    def gcs_local_port(self) -> int:
        return self.gcs_local_base + self.instance

    @property
    def remote_host(self) -> str:
        """Where telemetry goes before a peer speaks: this host (loopback unless bound elsewhere)."""
        return "127.0.0.1" if self.bind in ("0.0.0.0", "127.0.0.1") else self.bind


__all__ = ["COMPONENT_ID", "MavlinkEndpoint", "MavlinkSigning"]
