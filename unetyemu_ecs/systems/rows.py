"""Gather the fleet rows of entities that carry a component, sorted by row (deterministic)."""

from __future__ import annotations

from typing import Any, TypeVar

import esper
import numpy as np

from ..components.body import FleetSlot

C = TypeVar("C")


def gather_rows(component_type: type[C]) -> tuple[np.ndarray, list[C]]:
    """Return ``(rows (M,) intp, components)`` of every entity with a fleet slot and ``component_type``.

    Call only when ``fleet.version`` changed, never per step.
    """
    found: list[tuple[int, Any]] = sorted(
        ((slot.row, comp) for _, (slot, comp) in esper.get_components(FleetSlot, component_type)),
        key=lambda rc: rc[0])
    return np.array([r for r, _ in found], dtype=np.intp), [c for _, c in found]


def stack_params(items: list[Any], cls: type) -> Any:
    """Stack M parameter dataclasses into one ``cls`` whose fields are (M,) arrays (for vectorised laws)."""
    import dataclasses

    names = [f.name for f in dataclasses.fields(cls)]
    return cls(**{n: np.array([getattr(it, n) for it in items], dtype=float) for n in names})


def take_params(stacked: Any, idx: np.ndarray) -> Any:
    """Select the rows ``idx`` of a stacked parameter dataclass."""
    import dataclasses

    return dataclasses.replace(stacked, **{f.name: getattr(stacked, f.name)[idx]
                                           for f in dataclasses.fields(stacked)})
