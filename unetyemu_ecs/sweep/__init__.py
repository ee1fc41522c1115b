"""Parameter sweeps and Monte-Carlo campaigns on Ray: ``unetyemu sweep`` (docs in the README).

The cartesian product of world-file overrides x seeds, each run an independent
:class:`~unetyemu_ecs.app.Simulation` on one core of a local or remote Ray cluster, every run's world
checked before anything starts; one table of the runs' figures, a plot, failures reported, resumable.
"""

from .campaign import SweepError, SweepOptions, SweepResult, run_sweep
from .figures import FIGURES, run_figures
from .overrides import OverrideError, Parameter, parse_set
from .plan import RunSpec, SweepPlan, build_plan, validate_plan
from .worker import RunOutcome, RunTask, execute_run

__all__ = ["FIGURES", "OverrideError", "Parameter", "RunOutcome", "RunSpec", "RunTask", "SweepError", "SweepOptions",
           "SweepPlan", "SweepResult", "build_plan", "execute_run", "parse_set", "run_figures", "run_sweep",
           "validate_plan"]
