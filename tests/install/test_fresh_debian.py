"""The README's first set-up command works, as written, on a fresh Debian 12 (slow).

A minimal Debian 12 root (``debootstrap --variant=minbase``: no Python, no pip, like the
``debian:12`` container image) is built in a temporary directory, this working tree is copied in
(the files git tracks or would track: no ``.venv``, no ``runs/``) and the README's first command runs
there as root in a chroot with a clean environment. It must install everything it needs and run the
delivery scenario to the end. Then the same set-up runs a second time over the existing ``.venv``
(the run shortened to 5 simulated seconds, since the full run has just been shown) to show that the
command can be repeated.

Needs root, network access to a Debian mirror and to PyPI, and a few minutes (see the README's Tests
section). ``UNETYEMU_DEBIAN_MIRROR`` picks the mirror (default ``http://deb.debian.org/debian``).
Where the machine's HTTPS goes through an intercepting proxy whose CA is only in the host's bundle
(``PIP_CERT`` or ``SSL_CERT_FILE`` set), that bundle is handed to pip in the chroot as ``PIP_CERT``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from .readme import REPO_ROOT, readme_commands, repo_files

pytestmark = pytest.mark.slow

MIRROR = os.environ.get("UNETYEMU_DEBIAN_MIRROR", "http://deb.debian.org/debian")
SUITE = "bookworm"                     # Debian 12
CHROOT_REPO = Path("root/unetyemu_ecs")
CLEAN_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
SETUP_TIMEOUT_S = 3600                 # debootstrap, apt and pip downloads, the 150 s scenario, on a busy machine


def _sh(*args: str, timeout: float = 600, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(list(args), capture_output=True, text=True, timeout=timeout, **kw)


def _ensure_debootstrap() -> str:
    found = shutil.which("debootstrap")
    if found:
        return found
    done = _sh("apt-get", "install", "-y", "-q", "debootstrap", env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"})
    if done.returncode != 0:
        done = _sh("bash", "-c", "apt-get update -q && apt-get install -y -q debootstrap",
                   env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"})
    assert done.returncode == 0, f"could not install debootstrap:\n{done.stdout}\n{done.stderr}"
    return shutil.which("debootstrap") or "/usr/sbin/debootstrap"


def _host_ca_bundle() -> Path | None:
    for var in ("PIP_CERT", "SSL_CERT_FILE"):
        value = os.environ.get(var)
        if value and Path(value).is_file():
            return Path(value)
    return None


@pytest.fixture
def debian12_root(tmp_path: Path):
    """A fresh minimal Debian 12 root with /proc, /sys and /dev mounted; unmounted and removed after."""
    if not sys.platform.startswith("linux") or os.geteuid() != 0:
        pytest.skip("building a Debian root with debootstrap needs Linux and root")
    debootstrap = _ensure_debootstrap()
    root = tmp_path / "debian12"
    done = _sh(debootstrap, "--variant=minbase", SUITE, str(root), MIRROR, timeout=SETUP_TIMEOUT_S)
    assert done.returncode == 0, f"debootstrap {SUITE} from {MIRROR} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    shutil.copy("/etc/resolv.conf", root / "etc" / "resolv.conf")
    mounts = []
    try:
        for args, target in ((["-t", "proc", "proc"], "proc"), (["-t", "sysfs", "sysfs"], "sys"),
                             (["--rbind", "/dev"], "dev")):
            done = _sh("mount", *args, str(root / target))
            assert done.returncode == 0, done.stderr
            mounts.append(root / target)
        # a slave copy of /dev: unmounting it later can never unmount the host's /dev/pts or /dev/shm
        done = _sh("mount", "--make-rslave", str(root / "dev"))
        assert done.returncode == 0, done.stderr
        yield root
    finally:
        for target in reversed(mounts):
            _sh("umount", "-R", "-l", str(target))
        if not any(os.path.ismount(m) for m in mounts):
            shutil.rmtree(root, ignore_errors=True)


def _copy_working_tree(dest: Path) -> None:
    for rel in repo_files():
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO_ROOT / rel, dest / rel)


def _run_in_chroot(root: Path, command: str, log: Path) -> subprocess.CompletedProcess:
    env = {"PATH": CLEAN_PATH, "HOME": "/root", "TERM": "dumb", "LANG": "C.UTF-8"}
    bundle = _host_ca_bundle()
    if bundle is not None:
        shutil.copy(bundle, root / "etc" / "host-ca-bundle.crt")
        env["PIP_CERT"] = "/etc/host-ca-bundle.crt"
    argv = ["chroot", str(root), "/usr/bin/env", "-i", *(f"{k}={v}" for k, v in env.items()),
            "/bin/bash", "-c", f"cd /{CHROOT_REPO} && {command}"]
    with log.open("w") as out:
        done = subprocess.run(argv, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                              timeout=SETUP_TIMEOUT_S)
    return done


def test_readme_first_command_installs_and_runs_on_fresh_debian12(debian12_root: Path, tmp_path: Path):
    # GIVEN a fresh minimal Debian 12 (no python3, no pip) and a copy of this working tree in it
    root = debian12_root
    assert not (root / "usr/bin/python3").exists()
    repo = root / CHROOT_REPO
    _copy_working_tree(repo)
    assert not (repo / ".venv").exists()
    first = readme_commands()[0]

    # WHEN the README's first command runs there, as written, as root
    log = tmp_path / "first.log"
    done = _run_in_chroot(root, first, log)

    # THEN it succeeds, prints the summary and leaves the run's logs under runs/
    text = log.read_text(errors="replace")
    assert done.returncode == 0, f"exit {done.returncode}:\n{text[-6000:]}"
    assert (repo / ".venv" / "bin" / "unetyemu").exists()
    runs = sorted((repo / "runs").glob("urban_delivery*"))
    assert len(runs) == 1, runs
    summary = json.loads((runs[0] / "summary.json").read_text())
    assert summary["sim_time_s"] == pytest.approx(150.0, abs=0.01)
    names = {e["name"] for e in summary["entities"]}
    assert {"drone1", "drone2", "drone3", "truck1"} <= names
    assert len((runs[0] / "drone1.csv").read_text().splitlines()) > 1000    # 150 s at 10 Hz
    assert "drone1" in text

    # WHEN the same set-up runs again over the existing .venv (run shortened: the full run was shown above)
    again = tmp_path / "again.log"
    done = _run_in_chroot(root, f"{first} --duration 5", again)

    # THEN it succeeds too
    assert done.returncode == 0, f"second run exit {done.returncode}:\n{again.read_text(errors='replace')[-6000:]}"
    assert len(sorted((repo / "runs").glob("urban_delivery*"))) == 2
