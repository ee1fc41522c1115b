"""Check the names a mission refers to (pads, packages) against the world it will run in."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from ..config.schema import Path


def mission_reference_issues(spec: Any, layout: Any, package_names: Iterable[str]) -> list[tuple[Path, str]]:
    """Return ``(key path, message)`` for each pad or package name in ``spec`` that the world lacks."""
    pads = set(layout.pads)
    packages = set(package_names)
    out: list[tuple[Path, str]] = []
    for i, step in enumerate(spec.steps):
        pad = getattr(step, "pad", None)
        if pad is not None and pad not in pads:
            out.append((("steps", i, "pad"), f"unknown pad {pad!r} (pads in this world: "
                                             f"{', '.join(sorted(pads)) or 'none'})"))
        pkg = getattr(step, "package", None)
        if pkg is not None and pkg not in packages:
            out.append((("steps", i, "package"), f"unknown package {pkg!r} (packages in this world: "
                                                 f"{', '.join(sorted(packages)) or 'none'})"))
    return out
