"""The base of every system that works on the fleet rows of the entities carrying some components.

A :class:`FleetSystem` names the components an entity must carry (``requires``); before each step
it checks, in O(1), whether the ECS or the fleet changed since it last looked, and only then
gathers the rows and components again and lets the subclass stack its parameters (``gather``).
Adding a component to an entity after spawn (``aero_drag`` on a falling box), removing it, or
replacing it with other parameters therefore takes effect on the next step, and no system keeps
rows or parameters that the world no longer has.

How the change is seen: esper caches the answer of each component query and drops every cached
answer whenever any entity gains, loses or replaces a component. The list a query returns is
therefore the same object for as long as the structure is unchanged, and a new object after any
change; the system keeps the list it gathered from and compares identities.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import esper
import numpy as np

from ..components.body import FleetSlot
from ..fleet import row_selector
from ..world import StepContext


class FleetSystem(esper.Processor):
    """A system that acts on every fleet row whose entity carries all of ``requires``.

    Subclasses set ``phase`` (and ``order``), ``requires`` (component types; rows of entities with a
    :class:`FleetSlot` and all of them) and implement :meth:`update`; they may override
    :meth:`gather` to stack per-row parameters from the gathered components. After a gather:

    - ``rows`` : (M,) intp fleet rows, ascending (a deterministic order);
    - ``sel`` : the cheapest index of those rows (:func:`~unetyemu_ecs.fleet.row_selector`: a slice when
      they are contiguous; reads through it are views), for reading and writing whole-fleet arrays;
    - ``entities`` : (M,) int64 esper entity ids of those rows;
    - ``components`` : one list of M components per type in ``requires``, in row order.

    ``update`` runs only when M > 0.
    """

    requires: ClassVar[tuple[type, ...]] = ()

    def __init__(self) -> None:
        self._query: Any = None
        self._version = -1
        self.rows = np.empty(0, dtype=np.intp)
        self.sel: slice | np.ndarray = self.rows
        self.entities = np.empty(0, dtype=np.int64)
        self.components: tuple[list[Any], ...] = tuple([] for _ in self.requires)

    def refresh(self, ctx: StepContext) -> bool:
        """Gather again if the ECS or the fleet changed since the last gather; return ``M > 0``."""
        found = esper.get_components(FleetSlot, *self.requires)
        if found is not self._query or ctx.fleet.version != self._version:
            self._query = found
            self._version = ctx.fleet.version
            ordered = sorted(found, key=lambda ec: ec[1][0].row)
            self.rows = np.array([comps[0].row for _, comps in ordered], dtype=np.intp)
            self.sel = row_selector(self.rows)
            self.entities = np.array([ent for ent, _ in ordered], dtype=np.int64)
            self.components = tuple([comps[k + 1] for _, comps in ordered] for k in range(len(self.requires)))
            self.gather(ctx)
        return self.rows.size > 0

    def gather(self, ctx: StepContext) -> None:
        """Called after the rows changed: stack the parameters ``update`` needs (default: nothing)."""

    def process(self, ctx: StepContext) -> None:
        if self.refresh(ctx):
            self.update(ctx)

    def update(self, ctx: StepContext) -> None:
        """One step of work on ``rows`` (M > 0)."""
        raise NotImplementedError(f"{type(self).__name__} must implement update(ctx)")


def read_only(values: np.ndarray) -> np.ndarray:
    """``values`` marked read-only (what a law receives of the fleet: a view must not be written through)."""
    values.flags.writeable = False
    return values


def stack_params(items: list[Any], cls: type) -> Any:
    """Stack M parameter dataclasses into one ``cls`` whose fields are (M, ...) float arrays (for vectorised laws)."""
    names = [f.name for f in dataclasses.fields(cls)]
    if not items:
        return cls(**{n: np.zeros(0) for n in names})
    return cls(**{n: np.array([getattr(it, n) for it in items], dtype=float) for n in names})


def take_params(stacked: Any, idx: np.ndarray) -> Any:
    """Select the rows ``idx`` of a stacked parameter dataclass."""
    return dataclasses.replace(stacked, **{f.name: getattr(stacked, f.name)[idx]
                                           for f in dataclasses.fields(stacked)})


__all__ = ["FleetSystem", "read_only", "stack_params", "take_params"]
