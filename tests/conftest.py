"""Shared fixtures: a seeded RNG, paths, and a helper that writes world files."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
WORLDS = REPO_ROOT / "worlds"


def unetyemu_command() -> list[str]:
    """How to run the ``unetyemu`` CLI of the interpreter running the tests: the console script next to
    it (the venv's ``.venv/bin/unetyemu``), never another one found on PATH; else ``python -m``."""
    script = Path(sys.executable).with_name("unetyemu")
    return [str(script)] if script.exists() else [sys.executable, "-m", "unetyemu_ecs.cli"]


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


@pytest.fixture
def write_world(tmp_path: Path):
    """Write dedented YAML to a file in ``tmp_path`` and return its path."""

    def _write(text: str, name: str = "world.yaml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
        return path

    return _write
