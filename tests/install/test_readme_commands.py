"""The README's two set-up commands are what a new user runs and what CI runs (fast checks).

The commands themselves are run on a fresh Debian 12 root by ``test_fresh_debian.py`` (slow).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from .readme import REPO_ROOT, readme_commands

CI_RUN = REPO_ROOT / ".ci" / "run"


def test_readme_first_sh_block_holds_exactly_two_commands():
    # GIVEN the README  WHEN its first sh block is read  THEN it holds the two set-up commands, one a line
    assert len(readme_commands()) == 2, readme_commands()


def test_first_command_installs_into_a_venv_and_runs_the_delivery_world():
    # GIVEN the first command
    first = readme_commands()[0]
    # THEN it installs what apt must provide, creates .venv, installs the project there and runs the scenario
    assert first.startswith("apt-get update && apt-get install -y ")
    for package in ("python3-venv", "python3-dev", "g++", "libusb-1.0-0", "libgl1", "libegl1"):
        assert f" {package} " in first, package
    assert "python3 -m venv .venv && .venv/bin/pip install -e . &&" in first
    assert first.endswith(" && .venv/bin/unetyemu run worlds/urban_delivery.yaml")
    # AND it never installs outside the venv (PEP 668 refuses that on Debian 12 and Ubuntu 24.04)
    assert "python3 -m pip" not in first and " pip install" not in first.replace(".venv/bin/pip install", "")


def test_second_command_installs_test_extras_and_runs_pytest_from_the_venv():
    # GIVEN the second command
    second = readme_commands()[1]
    # THEN it also installs the Fast DDS peer's build dependencies and Chromium (the web view test) and runs
    # pytest with the venv's python,
    # on two workers (pytest-xdist, from the test extra) with the DDS tests grouped on one of them
    for package in ("python3-venv", "python3-dev", "g++", "libusb-1.0-0", "libgl1", "libegl1", "libfastrtps-dev",
                    "chromium"):
        assert f" {package} " in second, package
    assert "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' &&" in second
    assert second.endswith(" && .venv/bin/python -m pytest -n 2 --dist loadfile")


def test_ci_runs_the_readme_test_command():
    # GIVEN .ci/run  WHEN asked which command it runs  THEN it is the README's second command, verbatim
    out = subprocess.run(["bash", str(CI_RUN), "--print"], capture_output=True, text=True, timeout=30, check=True)
    assert out.stdout.rstrip("\n") == readme_commands()[1]


@pytest.mark.parametrize(("command_rc", "ci_rc"), [(0, 0), (3, 3), (5, 1)])
def test_ci_passes_on_the_exit_status_and_fails_when_no_test_ran(tmp_path: Path, command_rc: int, ci_rc: int):
    # GIVEN a checkout whose README's test command exits with command_rc (5: pytest collected no tests)
    (tmp_path / ".ci").mkdir()
    shutil.copy(CI_RUN, tmp_path / ".ci" / "run")
    (tmp_path / "README.md").write_text(f"# x\n\n```sh\ntrue\nexit {command_rc}\n```\n", encoding="utf-8")
    # WHEN CI runs
    done = subprocess.run(["bash", str(tmp_path / ".ci" / "run")], capture_output=True, text=True, timeout=30)
    # THEN it exits with the command's status, except that "no tests" is a failure
    assert done.returncode == ci_rc, done.stderr
    if command_rc == 5:
        assert "no tests" in done.stderr


def test_ci_fails_when_the_readme_has_no_test_command(tmp_path: Path):
    # GIVEN a README without a sh block
    (tmp_path / ".ci").mkdir()
    shutil.copy(CI_RUN, tmp_path / ".ci" / "run")
    (tmp_path / "README.md").write_text("# x\n\nno commands\n", encoding="utf-8")
    # WHEN CI runs  THEN it fails and says why
    done = subprocess.run(["bash", str(tmp_path / ".ci" / "run")], capture_output=True, text=True, timeout=30)
    assert done.returncode == 1
    assert "no test command" in done.stderr
