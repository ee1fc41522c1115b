"""Property-based fuzzing of the world loader: mutated shipped worlds either load cleanly or are refused
with ``file:line: key.path: message`` issues (``unetyemu validate`` exit 2) -- never a traceback, a hang
or unbounded memory; and a mutated world that loads also builds and steps.

The default run takes a few dozen examples; ``-m slow`` runs the many-example variants.
"""

from __future__ import annotations

import copy
import math
import resource
import signal
import subprocess
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from unetyemu_ecs import ConfigError, Simulation, load_world

from ..conftest import REPO_ROOT, WORLDS, unetyemu_command

WORLD_TEXTS = {p.name: p.read_text(encoding="utf-8") for p in sorted(WORLDS.glob("*.yaml"))}
WORLD_DOCS = {name: yaml.safe_load(text) for name, text in WORLD_TEXTS.items()}

EXAMPLE_TIME_LIMIT_S = 120          # a hang guard for one example, not a speed expectation
CLI_MEMORY_LIMIT_B = 2 << 30        # address space of one `unetyemu validate` (it needs ~1 GiB)


# ---------------------------------------------------------------------------------------------
# Mutations
# ---------------------------------------------------------------------------------------------
junk_values = st.one_of(
    st.integers(min_value=-(2**80), max_value=2**80),
    st.sampled_from([0, -1, 1, 2**31, 2**63, 2**70, 10**300, -(10**300)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 1e-300, -0.0, math.nan, math.inf, -math.inf, 0.001, 1e9]),
    st.text(max_size=20),
    st.sampled_from(["x" * 5000, "", "start_1", "roof_1", "package1", "quadrotor", "car", "all", "none", "urban"]),
    st.none(),
    st.booleans(),
    st.lists(st.integers(min_value=-5, max_value=5), max_size=4),
    st.lists(st.floats(allow_nan=True), max_size=4),
    st.dictionaries(st.text(max_size=6), st.integers(), max_size=3),
)


def _paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*prefix, i))
    return out


def _parent(doc: Any, path: tuple) -> tuple[Any, Any]:
    node = doc
    for part in path[:-1]:
        node = node[part]
    return node, path[-1]


@st.composite
def mutated_doc(draw: st.DrawFn, numbers_only: bool = False) -> Any:
    """A shipped world with 1-4 values replaced, scaled, deleted, or keys added."""
    doc = copy.deepcopy(WORLD_DOCS[draw(st.sampled_from(sorted(WORLD_DOCS)))])
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _parent(doc, path)
        value = parent[key]
        ops = ["scale"] if numbers_only else ["replace", "scale", "delete", "add_key"]
        op = draw(st.sampled_from(ops))
        if op == "scale" and isinstance(value, (int, float)) and not isinstance(value, bool):
            factor = draw(st.sampled_from([0.5, 0.9, 1.1, 2.0] if numbers_only else [-1, 0, 0.5, 2, 1e3, 1e9, 1e300]))
            scaled = value * factor
            parent[key] = int(scaled) if isinstance(value, int) and math.isfinite(scaled) else scaled
        elif op == "replace" or op == "scale":
            if not numbers_only:
                parent[key] = draw(junk_values)
        elif op == "delete":
            del parent[key]
        elif op == "add_key" and isinstance(value, dict):
            value[draw(st.text(min_size=1, max_size=8))] = draw(junk_values)
    return doc


@st.composite
def mutated_file(draw: st.DrawFn) -> bytes:
    """Bytes of a mutated world: a mutated document, then possibly a textual mutation of its YAML."""
    text = yaml.safe_dump(draw(mutated_doc()), sort_keys=False, allow_unicode=True)
    lines = text.splitlines(keepends=True) or ["\n"]
    op = draw(st.sampled_from(["none", "duplicate_line", "random_bytes", "deep_nesting", "alias_bomb",
                               "self_alias", "shared_anchor", "truncate", "original"]))
    if op == "duplicate_line":
        k = draw(st.integers(min_value=0, max_value=len(lines) - 1))
        lines.insert(k, lines[k])
    elif op == "deep_nesting":
        k = draw(st.integers(min_value=0, max_value=len(lines) - 1))
        n = draw(st.integers(min_value=1, max_value=600))
        head, sep, _ = lines[k].rstrip("\n").partition(": ")
        lines[k] = f"{head}{sep or ': '}{'[' * n}1{']' * n}\n"
    elif op == "alias_bomb":
        bomb = ["lol0: &l0 [a, a, a, a, a, a, a, a, a, a]\n"]
        bomb += [f"lol{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 10)}]\n" for i in range(1, 9)]
        lines = bomb + lines
    elif op == "self_alias":
        lines.append("loop: &loop [1, *loop]\n")
    elif op == "shared_anchor":
        lines.append("extra: &shared {imu: {}}\nmore: *shared\n")
    elif op == "truncate":
        cut = draw(st.integers(min_value=0, max_value=len(text)))
        return text[:cut].encode("utf-8", errors="replace")
    elif op == "original":
        return WORLD_TEXTS[draw(st.sampled_from(sorted(WORLD_TEXTS)))].encode()
    data = "".join(lines).encode("utf-8")
    if op == "random_bytes":
        at = draw(st.integers(min_value=0, max_value=len(data)))
        data = data[:at] + draw(st.binary(min_size=1, max_size=64)) + data[at:]
    return data


# ---------------------------------------------------------------------------------------------
# Checks
# ---------------------------------------------------------------------------------------------
class _Hang(Exception):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise _Hang(f"one example ran longer than {EXAMPLE_TIME_LIMIT_S} s")


def _load_or_refuse(path: Path):
    """Load ``path``; a refusal must be a ConfigError whose issues all name the file (and a line, unless
    the problem is the file as a whole). Any other exception fails the test. Returns the world or None."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(EXAMPLE_TIME_LIMIT_S)
    try:
        return load_world(path)
    except ConfigError as exc:
        assert exc.issues
        for issue in exc.issues:
            assert issue.file == str(path), str(issue)
            assert issue.line is not None or issue.path == (), str(issue)
            assert str(issue).startswith(f"{path}:"), str(issue)
        return None
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _peak_rss_b() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _run_in_process(data: bytes, tmp_path: Path) -> None:
    path = tmp_path / "fuzz.yaml"
    path.write_bytes(data)
    _load_or_refuse(path)


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CLI_MEMORY_LIMIT_B, CLI_MEMORY_LIMIT_B))


def _run_cli(data: bytes, tmp_path: Path) -> None:
    path = tmp_path / "fuzz.yaml"
    path.write_bytes(data)
    cmd = unetyemu_command()
    res = subprocess.run([*cmd, "validate", str(path)], cwd=REPO_ROOT, capture_output=True, text=True,
                         timeout=EXAMPLE_TIME_LIMIT_S, preexec_fn=_limit_memory)
    assert "Traceback" not in res.stderr, res.stderr
    assert res.returncode in (0, 2), (res.returncode, res.stderr[-2000:])
    if res.returncode == 2:
        assert res.stderr.strip(), "exit 2 without a message"
        assert str(path) in res.stderr, res.stderr[-2000:]
    else:
        assert "OK" in res.stdout


def _build_and_step(doc: Any, tmp_path: Path) -> bool:
    path = tmp_path / "valid.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    world = _load_or_refuse(path)
    if world is None:
        return False
    with Simulation(world) as sim:
        sim.step(3)
    return True


FUZZ = settings(deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.function_scoped_fixture])


# ---------------------------------------------------------------------------------------------
# Default run: a few dozen examples
# ---------------------------------------------------------------------------------------------
@settings(FUZZ, max_examples=25)
@given(data=mutated_file())
def test_a_mutated_world_loads_or_is_refused_with_file_and_line(data, tmp_path):
    rss_before = _peak_rss_b()
    _run_in_process(data, tmp_path)
    # the loader's own memory stays bounded (the bounds allow ~50 MB of document)
    assert _peak_rss_b() - rss_before < 1 << 30


@settings(FUZZ, max_examples=3)
@given(data=mutated_file())
def test_unetyemu_validate_on_a_mutated_world_exits_0_or_2_with_a_message_and_no_traceback(data, tmp_path):
    _run_cli(data, tmp_path)


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/null", "/dev/urandom"])
def test_unetyemu_validate_on_a_device_exits_2_at_once(device):
    cmd = unetyemu_command()
    res = subprocess.run([*cmd, "validate", device], capture_output=True, text=True, timeout=EXAMPLE_TIME_LIMIT_S,
                         preexec_fn=_limit_memory)
    assert res.returncode == 2 and res.stderr.startswith(f"{device}: <root>: ") and "Traceback" not in res.stderr


@settings(FUZZ, max_examples=2)
@given(doc=mutated_doc(numbers_only=True))
def test_a_mutated_world_that_loads_also_builds_and_steps(doc, tmp_path):
    _build_and_step(doc, tmp_path)


# ---------------------------------------------------------------------------------------------
# Slow variants: many more examples
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
@settings(FUZZ, max_examples=1000)
@given(data=mutated_file())
def test_many_mutated_worlds_load_or_are_refused_with_file_and_line(data, tmp_path):
    _run_in_process(data, tmp_path)


@pytest.mark.slow
@settings(FUZZ, max_examples=40)
@given(data=mutated_file())
def test_unetyemu_validate_on_many_mutated_worlds_exits_0_or_2(data, tmp_path):
    _run_cli(data, tmp_path)


@pytest.mark.slow
@settings(FUZZ, max_examples=20)
@given(doc=mutated_doc(numbers_only=True))
def test_many_mutated_worlds_that_load_also_build_and_step(doc, tmp_path):
    _build_and_step(doc, tmp_path)
