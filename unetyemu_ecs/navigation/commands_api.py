"""The Python API of the navigation modes: ``Simulation.takeoff``, ``land``, ``return_to_launch``,
``set_nav_mode``, ``set_param`` ... (a mixin of :class:`~unetyemu_ecs.app.Simulation`).

Each method checks its arguments with :mod:`unetyemu_ecs.command_checks` (``ValueError`` naming what
is wrong), queues the command and returns its id; the result (accepted, or rejected with a reason)
appears in :meth:`Simulation.command_result` after the next step.
"""

from __future__ import annotations


class NavigationApi:
    """Navigation-mode commands of a :class:`~unetyemu_ecs.app.Simulation` (mixed into it)."""
