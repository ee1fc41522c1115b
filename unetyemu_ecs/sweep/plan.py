"""A sweep's runs: the cartesian product of parameter values x seeds, each checked before anything runs.

Every run has a stable id made of its parameters and seed plus a hash of them, so that two runs never
share an output directory and a resumed sweep recognises the runs it has already finished.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path as FsPath
from typing import Any

from ..config.limits import MAX_WORLD_FILE_BYTES, MAX_WORLD_NESTING, MAX_WORLD_NODES
from ..config.schema import ConfigError, Issue, Path, SourceMap
from ..config.world_file import WorldDefinition, resolve_world
from ..config.yaml_source import load_yaml_text, prescan, read_text_file
from .overrides import OverrideError, Parameter, apply_overrides, canonical, check_distinct, resolve_key

MAX_RUNS = 100_000          # one sweep: beyond this the plan itself (and its table) is the problem
MAX_SEED = 2**63 - 1
RUN_NAME_CHARS = 80         # readable part of a run's directory name


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: which values, which seed, and where its outputs go (``runs/<run_id>``)."""

    run_id: str
    values: tuple[tuple[str, Any, str], ...]      # (key, value, value as written) per parameter
    overrides: tuple[tuple[Path, Any], ...]       # (concrete world-file path, value)
    seed: int

    @property
    def combination(self) -> str:
        """The run's world-file overrides as one text: runs that differ only in their seed share it."""
        return json.dumps([[list(path), v] for path, v in self.overrides], default=str)

    @property
    def label(self) -> str:
        """``packages.parcel.mass_kg=1.5, seed=3``: how messages name this run."""
        return ", ".join([f"{k}={t}" for k, _v, t in self.values] + [f"seed={self.seed}"])


@dataclass(frozen=True)
class SweepPlan:
    """What a sweep runs: the world file's text, the parameters, the seeds and the runs."""

    world_file: str                 # as given (messages, the table)
    world_text: str                 # sent to the workers: a cluster's nodes need not have the file
    world_sha256: str
    parameters: tuple[Parameter, ...]
    seeds: tuple[int, ...]
    runs: tuple[RunSpec, ...]

    @cached_property
    def world_name(self) -> str:
        doc, _src = load_yaml_text(self.world_text, self.world_file)
        name = (doc.get("world") or {}).get("name") if isinstance(doc, dict) else None
        return str(name) if isinstance(name, str) and name else FsPath(self.world_file).stem


def run_id(values: tuple[tuple[str, Any, str], ...], overrides: tuple[tuple[Path, Any], ...], seed: int) -> str:
    """``mass_kg=1.5-preset=small-seed3-1a2b3c4d``: readable, and unique through the hash of every
    world-file path set, its value and the seed. The same run has the same id however its values
    were written (``1.0``, ``1.00``) and in whatever order the ``--set`` came (a resume finds it)."""
    canon = json.dumps(sorted([json.dumps(list(path)), canonical(v)] for path, v in overrides) + [["seed", seed]],
                       separators=(",", ":"))
    digest = hashlib.sha256(canon.encode()).hexdigest()[:10]
    by_path = sorted(zip(overrides, values), key=lambda pair: json.dumps(list(pair[0][0])))
    words = [f"{k.rsplit('.', 1)[-1]}={canonical(v).strip(chr(34))}" for _o, (k, v, _t) in by_path]
    readable = re.sub(r"[^A-Za-z0-9._=+-]+", "_", "-".join(words))[:RUN_NAME_CHARS].strip("_-")
    return f"{readable}-seed{seed}-{digest}" if readable else f"seed{seed}-{digest}"


def _world_doc(world_file: str | FsPath) -> tuple[str, Any, SourceMap]:
    text = read_text_file(world_file, MAX_WORLD_FILE_BYTES, "world file")
    prescan(text, str(world_file), max_depth=MAX_WORLD_NESTING, max_nodes=MAX_WORLD_NODES, what="world file")
    doc, src = load_yaml_text(text, str(world_file))
    if not isinstance(doc, dict):
        raise ConfigError([Issue(str(world_file), 1, (), "a world file is a mapping (world, scene, packages, "
                                                         "vehicles)")])
    return text, doc, src


def build_plan(world_file: str | FsPath, parameters: list[Parameter], seeds: int = 1,
               first_seed: int | None = None) -> SweepPlan:
    """Every combination of the parameters' values, each with ``seeds`` seeds from ``first_seed`` (default:
    the world file's own seed).

    Raises
    ------
    ConfigError
        The world file cannot be read.
    OverrideError
        A parameter names nothing in the file, is given twice, or the sweep is too large.
    """
    text, doc, src = _world_doc(world_file)
    if not isinstance(seeds, int) or isinstance(seeds, bool) or seeds < 1:
        raise ValueError(f"seeds must be a positive number of seeds per combination, got {seeds!r}")
    if first_seed is None:
        world = doc.get("world") if isinstance(doc.get("world"), dict) else {}
        first_seed = world.get("seed", 0) if isinstance(world.get("seed", 0), int) else 0
    if not 0 <= first_seed or first_seed + seeds - 1 > MAX_SEED:
        raise ValueError(f"seeds {first_seed}..{first_seed + seeds - 1} leave [0, 2**63 - 1]")
    paths = [resolve_key(doc, p.key, str(world_file)) for p in parameters]
    check_distinct(parameters, paths)
    n_runs = seeds
    for p in parameters:
        n_runs *= len(p.values)
    if n_runs > MAX_RUNS:
        raise OverrideError(f"the sweep has {n_runs} runs (values x seeds); at most {MAX_RUNS} in one sweep")
    runs = []
    for combo in itertools.product(*[range(len(p.values)) for p in parameters]):
        values = tuple((p.key, p.values[i], p.texts[i]) for p, i in zip(parameters, combo))
        overrides = tuple((path, p.values[i]) for p, path, i in zip(parameters, paths, combo))
        for seed in range(first_seed, first_seed + seeds):
            runs.append(RunSpec(run_id(values, overrides, seed), values, overrides, seed))
    return SweepPlan(str(world_file), text, hashlib.sha256(text.encode()).hexdigest(), tuple(parameters),
                     tuple(range(first_seed, first_seed + seeds)), tuple(runs))


def resolve_run(plan: SweepPlan, run: RunSpec, extra: tuple[tuple[Path, Any], ...] = ()) -> WorldDefinition:
    """The world of one run: the file with the run's overrides (and ``extra`` ones) and its seed."""
    doc, src = load_yaml_text(plan.world_text, plan.world_file)
    return resolve_world(apply_overrides(doc, [*run.overrides, *extra]), src, seed=run.seed)


def _seed_shapes_world(doc: dict[str, Any]) -> bool:
    """Whether the seed changes more than noise and wind: a generated city without its own ``scene.seed``
    is drawn from the world's seed, so pads, parking and buildings move with it."""
    scene = doc.get("scene") if isinstance(doc.get("scene"), dict) else {}
    return scene.get("generator") == "urban" and scene.get("seed") is None


def validate_plan(plan: SweepPlan) -> list[tuple[RunSpec, ConfigError]]:
    """Load every distinct world of the plan (one per combination, or per combination and seed when the
    seed shapes the city); return the runs whose world is invalid, with the loader's errors."""
    doc, _src = load_yaml_text(plan.world_text, plan.world_file)
    bad: list[tuple[RunSpec, ConfigError]] = []
    checked: dict[Any, ConfigError | None] = {}
    for run in plan.runs:
        applied = apply_overrides(doc, list(run.overrides))
        key = (run.combination, run.seed if _seed_shapes_world(applied) else None)
        if key not in checked:
            try:
                resolve_run(plan, run)
                checked[key] = None
            except ConfigError as exc:
                checked[key] = exc
        if checked[key] is not None:
            bad.append((run, checked[key]))         # type: ignore[arg-type]
    return bad


def explain_invalid(plan: SweepPlan, bad: list[tuple[RunSpec, ConfigError]], limit: int = 20) -> str:
    """The loader's errors of the invalid runs, each once, traced to the ``--set`` that touches its path
    and followed by the parameter combinations it occurs in."""
    found: dict[str, list[str]] = {}            # error text -> combinations
    for run, exc in bad:
        combo = ", ".join(f"{k}={t}" for k, _v, t in run.values) or "no parameters"
        for issue in exc.issues:
            causes = [f"--set {k}={t}" for (path, _v), (k, _v2, t) in zip(run.overrides, run.values)
                      if issue.path and (issue.path[:len(path)] == path or path[:len(issue.path)] == issue.path)]
            text = f"{issue}" + (f"  (from {', '.join(causes)})" if causes else "")
            combos = found.setdefault(text, [])
            if combo not in combos:
                combos.append(combo)
    lines = []
    for text, combos in list(found.items())[:limit]:
        shown = "; ".join(combos[:3]) + (f"; and {len(combos) - 3} more" if len(combos) > 3 else "")
        lines += [f"  {text}", f"      with {shown}"]
    combos_all = {tuple(t for _k, _v, t in r.values) for r in plan.runs}
    bad_combos = {tuple(t for _k, _v, t in r.values) for r, _e in bad}
    head = (f"{len(bad_combos)} of {len(combos_all)} parameter combinations give an invalid world "
            f"({len(bad)} of {len(plan.runs)} runs); nothing was run:")
    more = [f"  ... and {len(found) - limit} more problems"] if len(found) > limit else []
    return "\n".join([head, *lines, *more])


__all__ = ["RunSpec", "SweepPlan", "build_plan", "explain_invalid", "resolve_run", "run_id", "validate_plan"]
