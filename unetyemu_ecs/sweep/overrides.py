"""World-file overrides by key path: ``--set packages.parcel.mass_kg=0.5,1.0,1.5``.

A key path walks the world file's mappings by key and its lists by the item's ``name`` (vehicles,
packages, pads...) or by index (``vehicles.0.preset``, ``...mission.steps.1.altitude_m``). Values are
YAML (``2.5``, ``true``, ``small``, ``[1.0, 0.0]``, ``"a,b"``), separated by commas outside brackets and
quotes. An override is resolved against the parsed document to a concrete path of keys and indexes,
so that the loader's own errors (which name ``vehicles[0].preset`` and its line in the file) can be
traced back to the ``--set`` that caused them.
"""

from __future__ import annotations

import copy
import json
import re
from dataclasses import dataclass
from typing import Any

import yaml

from ..config.schema import ConfigError, Path, format_path
from ..config.yaml_source import prescan

MAX_VALUES = 1_000          # values of one --set: a sweep of more runs than this per axis is a typo
MAX_KEY_DEPTH = 16          # a world file nests ~9 levels deep
MAX_VALUE_CHARS = 10_000    # one value: a whole mission block is a few kB
MAX_VALUE_NESTING = 16      # a value holds at most a block of a world file
MAX_VALUE_NODES = 10_000
SEED_PATH = ("world", "seed")
_SEGMENT = re.compile(r"[A-Za-z0-9_]+")


class OverrideError(ValueError):
    """A ``--set`` that cannot be parsed or names nothing in the world file; the message says which."""


@dataclass(frozen=True)
class Parameter:
    """One swept parameter: the key path as the user wrote it and the values it takes."""

    key: str                        # "packages.parcel.mass_kg"
    values: tuple[Any, ...]         # parsed YAML values, in the order given
    texts: tuple[str, ...]          # the values as written (for names and tables)


def _split_values(text: str) -> list[str]:
    """Split at commas outside brackets, braces and quotes: ``1,[2, 3],"a,b"`` -> 3 values."""
    out, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            out.append(text[start:i])
            start = i + 1
    out.append(text[start:])
    return [part.strip() for part in out]


def parse_set(text: str) -> Parameter:
    """Parse one ``--set KEY.PATH=V1,V2,...``; raise :class:`OverrideError` naming what is wrong."""
    where = f"--set {text!r}"
    key, sep, values_text = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise OverrideError(f"{where}: expected KEY.PATH=VALUE[,VALUE...], e.g. packages.parcel.mass_kg=0.5,1.0")
    segments = key.split(".")
    if len(segments) > MAX_KEY_DEPTH or not all(_SEGMENT.fullmatch(s) for s in segments):
        raise OverrideError(f"{where}: {key!r} is not a key path (names or indexes joined by dots, "
                            "e.g. vehicles.drone1.preset)")
    if tuple(segments) == SEED_PATH:
        raise OverrideError(f"{where}: seeds are swept with --seeds N (and --first-seed S), not with --set")
    texts = _split_values(values_text)
    if any(not t for t in texts):
        raise OverrideError(f"{where}: an empty value (two commas in a row, or a comma at the end?)")
    if len(texts) > MAX_VALUES:
        raise OverrideError(f"{where}: {len(texts)} values; at most {MAX_VALUES} per parameter")
    values = []
    for t in texts:
        if len(t) > MAX_VALUE_CHARS:
            raise OverrideError(f"{where}: a value of {len(t)} characters; at most {MAX_VALUE_CHARS}")
        try:
            prescan(t, where, max_depth=MAX_VALUE_NESTING, max_nodes=MAX_VALUE_NODES, aliases=False, what="--set value")
            values.append(yaml.safe_load(t))
        except ConfigError as exc:
            raise OverrideError(f"{where}: value {t[:40]!r}: {exc.issues[0].message}") from None
        except yaml.YAMLError as exc:
            raise OverrideError(f"{where}: value {t!r} is not YAML: {getattr(exc, 'problem', None) or exc}") from None
        if isinstance(values[-1], dict) and not values[-1]:
            raise OverrideError(f"{where}: value {t!r} is empty")
    canon = [canonical(v) for v in values]
    if len(set(canon)) != len(canon):
        raise OverrideError(f"{where}: a value is given twice ({', '.join(t for t, c in zip(texts, canon) if canon.count(c) > 1)} "
                            "are the same value)")
    return Parameter(key, tuple(values), tuple(texts))


def canonical(value: Any) -> str:
    """One text per value, however it was written (``1``, ``1.0`` and ``1.00``; ``[1,0]`` and ``[1, 0]``):
    the world file reads them alike."""
    def numbers_as_floats(v: Any) -> Any:
        if isinstance(v, int) and not isinstance(v, bool):
            return float(v)
        if isinstance(v, list):
            return [numbers_as_floats(x) for x in v]
        if isinstance(v, dict):
            return {str(k): numbers_as_floats(x) for k, x in v.items()}
        return v

    return json.dumps(numbers_as_floats(value), sort_keys=True, separators=(",", ":"), default=str)


def check_distinct(params: list[Parameter], paths: list[Path]) -> None:
    """Two ``--set`` of one value (``packages.parcel.mass_kg`` and ``packages.0.mass_kg``), or of a value
    and a block that holds it, would make the product ambiguous."""
    for i, (p, path) in enumerate(zip(params, paths)):
        for q, other in zip(params[:i], paths[:i]):
            if path == other:
                raise OverrideError(f"--set {p.key}: the same value as --set {q.key} ({format_path(path)}); list "
                                    f"every value in one --set ({q.key}=V1,V2,...)")
            if path[:len(other)] == other or other[:len(path)] == path:
                inner, outer = (p, q) if len(path) > len(other) else (q, p)
                raise OverrideError(f"--set {inner.key} lies inside --set {outer.key}; sweep one or the other")


def resolve_key(doc: Any, key: str, file: str) -> Path:
    """The concrete path (keys and list indexes) of ``key`` in the parsed world ``doc``.

    Missing mappings on the way are allowed (``world.wind.speed_m_s`` in a file without ``wind:``; the
    schema then checks the keys); a list item must exist, by its ``name`` or its index.
    """
    where = f"--set {key}"
    node: Any = doc
    path: list[str | int] = []
    segments = key.split(".")
    for depth, seg in enumerate(segments):
        last = depth == len(segments) - 1
        if isinstance(node, list):
            if seg.isdigit():
                index = int(seg)
                if index >= len(node):
                    raise OverrideError(f"{where}: {format_path(tuple(path))} in {file} has {len(node)} items; "
                                        f"there is no index {index}")
            else:
                names = [item.get("name") for item in node if isinstance(item, dict)]
                if seg not in names:
                    known = ", ".join(str(n) for n in names if n is not None) or "none has a name"
                    raise OverrideError(f"{where}: no item named {seg!r} in {format_path(tuple(path))} of {file} "
                                        f"(names: {known}; or use an index)")
                index = names.index(seg)
            path.append(index)
            node = node[index]
        elif isinstance(node, dict) or node is None:
            path.append(seg)
            node = (node or {}).get(seg)
        else:
            raise OverrideError(f"{where}: {format_path(tuple(path))} in {file} is a value ({node!r}), "
                                f"it has no {seg!r}")
        if last:
            break
    return tuple(path)


def apply_overrides(doc: Any, overrides: list[tuple[Path, Any]]) -> Any:
    """A copy of ``doc`` with each (concrete path, value) set; mappings missing on the way are created."""
    out = copy.deepcopy(doc)
    for path, value in overrides:
        node = out
        for part, nxt in zip(path[:-1], path[1:]):
            child = node[part] if isinstance(node, list) else node.get(part)
            if child is None:
                child = [] if isinstance(nxt, int) else {}
                node[part] = child
            node = child
        node[path[-1]] = copy.deepcopy(value)
    return out


def value_text(value: Any) -> str:
    """A value as a short YAML flow text (tables, run names, plot labels)."""
    if isinstance(value, str):
        return value
    return yaml.safe_dump(value, default_flow_style=True, width=1_000).strip().removesuffix("...").strip()


__all__ = ["OverrideError", "Parameter", "apply_overrides", "canonical", "check_distinct", "parse_set", "resolve_key",
           "value_text"]
