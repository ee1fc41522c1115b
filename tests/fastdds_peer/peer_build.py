"""Compile the Fast DDS peer (peer.cpp + the committed fastddsgen output) once per source change.

Needs ``g++`` and Debian's ``libfastrtps-dev`` (Fast DDS 2.9, pulls in libfastcdr-dev); the README's
test command and ``.ci/run`` install them. The binary is cached in ``build/`` under a hash of the sources.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCES = [HERE / "peer.cpp", HERE / "gen" / "ros2_types.cxx", HERE / "gen" / "ros2_typesPubSubTypes.cxx"]
HEADERS = [HERE / "gen" / "ros2_types.h", HERE / "gen" / "ros2_typesPubSubTypes.h"]
NEEDS = "Fast DDS 2.9 and a C++ compiler: apt-get install -y g++ libfastrtps-dev"


class PeerBuildError(RuntimeError):
    """The peer cannot be built here; the message says what is missing."""


def build_peer() -> Path:
    """Path of the compiled peer, building it if the sources changed."""
    compiler = shutil.which("g++")
    if compiler is None or not Path("/usr/include/fastdds/dds/domain/DomainParticipant.hpp").exists():
        raise PeerBuildError(f"the Fast DDS interop tests need {NEEDS}")
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in SOURCES + HEADERS)).hexdigest()[:16]
    exe = HERE / "build" / f"fastdds_peer-{digest}"
    if exe.exists():
        return exe
    exe.parent.mkdir(exist_ok=True)
    tmp = exe.with_suffix(".tmp")
    cmd = [compiler, "-std=c++17", "-O1", f"-I{HERE}", "-o", str(tmp), *map(str, SOURCES),
           "-lfastrtps", "-lfastcdr", "-lpthread"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise PeerBuildError(f"building the Fast DDS peer failed ({' '.join(cmd)}):\n{done.stderr[-3000:]}")
    tmp.rename(exe)
    return exe
