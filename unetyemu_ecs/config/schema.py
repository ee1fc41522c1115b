"""Typed, located validation of configuration data against dataclasses.

A world file (and every plugin component's parameter block) is described by frozen dataclasses whose
type hints are the schema: ``Annotated[float, Gt(0)]`` is a strictly positive number,
``tuple[float, float, float]`` a 3-vector, ``Literal["a", "b"]`` a choice, ``list[X]`` and
``dict[str, X]`` containers, ``X | None`` an optional value. :func:`convert` turns parsed YAML into
those dataclasses and collects every problem as an :class:`Issue` naming the file, the line and the
key path, so that a user sees all mistakes of a file at once and nothing starts.

Cross-field rules live in a dataclass's ``__post_init__``; a ``ValueError`` raised there is reported
at the path of that dataclass.
"""

from __future__ import annotations

import dataclasses
import math
import types
from dataclasses import dataclass
from typing import Annotated, Any, Literal, Union, get_args, get_origin, get_type_hints

Path = tuple[str | int, ...]


# ---------------------------------------------------------------------------------------------
# Constraint markers used inside Annotated[...]
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class Gt:
    """Value must be strictly greater than ``bound``."""

    bound: float

    def check(self, v: Any) -> str | None:
        return None if v > self.bound else f"must be > {self.bound:g}, got {v!r}"


@dataclass(frozen=True, slots=True)
class Ge:
    """Value must be greater than or equal to ``bound``."""

    bound: float

    def check(self, v: Any) -> str | None:
        return None if v >= self.bound else f"must be >= {self.bound:g}, got {v!r}"


@dataclass(frozen=True, slots=True)
class Lt:
    """Value must be strictly less than ``bound``."""

    bound: float

    def check(self, v: Any) -> str | None:
        return None if v < self.bound else f"must be < {self.bound:g}, got {v!r}"


@dataclass(frozen=True, slots=True)
class Le:
    """Value must be less than or equal to ``bound``."""

    bound: float

    def check(self, v: Any) -> str | None:
        return None if v <= self.bound else f"must be <= {self.bound:g}, got {v!r}"


@dataclass(frozen=True, slots=True)
class Each:
    """Apply a constraint to every element of a vector or list."""

    inner: Gt | Ge | Lt | Le

    def check(self, v: Any) -> str | None:
        for i, x in enumerate(v):
            msg = self.inner.check(x)
            if msg is not None:
                return f"element {i} {msg}"
        return None


@dataclass(frozen=True, slots=True)
class Ordered:
    """A 2-element range ``[low, high]`` must have ``low <= high``."""

    def check(self, v: Any) -> str | None:
        return None if v[0] <= v[1] else f"range must be [low, high] with low <= high, got {list(v)}"


@dataclass(frozen=True, slots=True)
class MaxLen:
    """A string or container must have at most ``n`` elements (checked before its elements are)."""

    n: int

    def check(self, v: Any) -> str | None:
        if len(v) <= self.n:
            return None
        what = "characters" if isinstance(v, str) else "elements"
        return f"must have at most {self.n} {what}, got {len(v)}"


@dataclass(frozen=True, slots=True)
class NonEmpty:
    """A string or container must not be empty."""

    def check(self, v: Any) -> str | None:
        return None if len(v) > 0 else "must not be empty"


# ---------------------------------------------------------------------------------------------
# Issues
# ---------------------------------------------------------------------------------------------
def format_path(path: Path) -> str:
    """Render ``("vehicles", 1, "preset")`` as ``vehicles[1].preset``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out or "<root>"


@dataclass(frozen=True, slots=True)
class Issue:
    """One problem found in a configuration source."""

    file: str
    line: int | None
    path: Path
    message: str

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}" if self.line is not None else self.file
        return f"{where}: {format_path(self.path)}: {self.message}"


class FieldError(ValueError):
    """Raise from a config dataclass's ``__post_init__`` to report a problem at one of its fields."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(message)


class ConfigError(ValueError):
    """Raised when a configuration source has one or more issues; ``str()`` lists them all."""

    def __init__(self, issues: list[Issue]) -> None:
        self.issues = list(issues)
        super().__init__("\n".join(str(i) for i in self.issues))


class SourceMap:
    """Where each key path of a parsed document starts (1-based line numbers)."""

    def __init__(self, file: str, lines: dict[Path, int] | None = None) -> None:
        self.file = file
        self.lines: dict[Path, int] = dict(lines or {})

    def line_of(self, path: Path) -> int | None:
        """Line of ``path``, or of its nearest ancestor that has one."""
        for n in range(len(path), -1, -1):
            line = self.lines.get(tuple(path[:n]))
            if line is not None:
                return line
        return None

    def issue(self, path: Path, message: str) -> Issue:
        return Issue(self.file, self.line_of(path), tuple(path), message)


# ---------------------------------------------------------------------------------------------
# Conversion
# ---------------------------------------------------------------------------------------------
class _Invalid:
    """Sentinel for a value that failed conversion (the issue is already recorded)."""

    def __repr__(self) -> str:
        return "<invalid>"


INVALID: Any = _Invalid()


def _type_name(tp: Any) -> str:
    origin = get_origin(tp)
    if origin is Annotated:
        return _type_name(get_args(tp)[0])
    if dataclasses.is_dataclass(tp):
        return "mapping"
    if tp is float:
        return "number"
    if tp is int:
        return "integer"
    if tp is str:
        return "string"
    if tp is bool:
        return "boolean (true/false)"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_type_name(args[0])}s"
        return f"list of {len(args)} {_type_name(args[0])}s"
    if origin is list:
        return f"list of {_type_name(get_args(tp)[0])}s"
    if origin is dict:
        return "mapping"
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in get_args(tp))
    if tp is type(None):
        return "null"
    return getattr(tp, "__name__", str(tp))


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"boolean {value!r}"
    if isinstance(value, (int, float)):
        return f"number {value!r}"
    if isinstance(value, str):
        return f"string {value!r}"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return type(value).__name__


def convert(value: Any, tp: Any, path: Path, src: SourceMap, issues: list[Issue]) -> Any:
    """Convert parsed YAML ``value`` to type ``tp``; record problems in ``issues``.

    Returns the converted value, or :data:`INVALID` if it could not be converted.
    """
    origin = get_origin(tp)

    if origin is Annotated:
        base, *markers = get_args(tp)
        for marker in markers:          # a list too long is refused before its elements are converted
            if isinstance(marker, MaxLen) and isinstance(value, (str, list, dict)):
                msg = marker.check(value)
                if msg is not None:
                    issues.append(src.issue(path, msg))
                    return INVALID
        out = convert(value, base, path, src, issues)
        if out is INVALID:
            return INVALID
        for marker in markers:
            check = getattr(marker, "check", None)
            if check is None:
                continue
            msg = check(out)
            if msg is not None:
                issues.append(src.issue(path, msg))
                return INVALID
        return out

    if tp is Any:
        return value

    if origin in (Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        if len(non_none) == 1:
            return convert(value, non_none[0], path, src, issues)
        # Try each alternative silently; report the expected set if none fits.
        for alt in non_none:
            trial: list[Issue] = []
            out = convert(value, alt, path, src, trial)
            if not trial:
                return out
        issues.append(src.issue(path, f"expected {_type_name(tp)}, got {_describe(value)}"))
        return INVALID

    if dataclasses.is_dataclass(tp):
        return _convert_dataclass(value, tp, path, src, issues)

    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            issues.append(src.issue(path, f"expected a number, got {_describe(value)}"))
            return INVALID
        try:
            out_f = float(value)
        except OverflowError:       # an integer beyond 1.8e308
            issues.append(src.issue(path, "must be a finite number, got an integer beyond 1.8e308"))
            return INVALID
        if not math.isfinite(out_f):
            issues.append(src.issue(path, f"must be a finite number, got {value!r}"))
            return INVALID
        return out_f

    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            issues.append(src.issue(path, f"expected an integer, got {_describe(value)}"))
            return INVALID
        return value

    if tp is str:
        if not isinstance(value, str):
            issues.append(src.issue(path, f"expected a string, got {_describe(value)}"))
            return INVALID
        return value

    if tp is bool:
        if not isinstance(value, bool):
            issues.append(src.issue(path, f"expected true or false, got {_describe(value)}"))
            return INVALID
        return value

    if origin is Literal:
        choices = get_args(tp)
        if value not in choices or isinstance(value, bool) != any(isinstance(c, bool) for c in choices):
            listed = ", ".join(str(c) for c in choices)
            issues.append(src.issue(path, f"unknown value {value!r} (expected one of: {listed})"))
            return INVALID
        return value

    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, list):
            issues.append(src.issue(path, f"expected {_type_name(tp)}, got {_describe(value)}"))
            return INVALID
        variadic = len(args) == 2 and args[1] is Ellipsis
        if not variadic and len(value) != len(args):
            issues.append(src.issue(path, f"expected {_type_name(tp)}, got {len(value)} element(s)"))
            return INVALID
        elem_types = [args[0]] * len(value) if variadic else list(args)
        out = [convert(v, t, (*path, i), src, issues) for i, (v, t) in enumerate(zip(value, elem_types))]
        return INVALID if any(o is INVALID for o in out) else tuple(out)

    if origin is list:
        (elem,) = get_args(tp)
        if value is None:  # `key:` with nothing under it
            return []
        if not isinstance(value, list):
            issues.append(src.issue(path, f"expected {_type_name(tp)}, got {_describe(value)}"))
            return INVALID
        out = [convert(v, elem, (*path, i), src, issues) for i, v in enumerate(value)]
        return INVALID if any(o is INVALID for o in out) else out

    if origin is dict:
        key_t, val_t = get_args(tp)
        if value is None:
            return {}
        if not isinstance(value, dict):
            issues.append(src.issue(path, f"expected a mapping, got {_describe(value)}"))
            return INVALID
        out_d: dict[Any, Any] = {}
        bad = False
        for k, v in value.items():
            ck = convert(k, key_t, (*path, k), src, issues)
            cv = convert(v, val_t, (*path, k), src, issues)
            bad |= ck is INVALID or cv is INVALID
            out_d[ck] = cv
        return INVALID if bad else out_d

    raise TypeError(f"schema type {tp!r} at {format_path(path)} is not supported")


def _convert_dataclass(value: Any, cls: type, path: Path, src: SourceMap, issues: list[Issue]) -> Any:
    if value is None:
        value = {}
    if not isinstance(value, dict):
        issues.append(src.issue(path, f"expected a mapping, got {_describe(value)}"))
        return INVALID
    hints = get_type_hints(cls, include_extras=True)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    n_before = len(issues)
    for key in value:
        if key not in fields:
            allowed = ", ".join(sorted(fields)) or "(none)"
            issues.append(src.issue((*path, key), f"unknown key {key!r} (allowed: {allowed})"))
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        if name in value:
            kwargs[name] = convert(value[name], hints[name], (*path, name), src, issues)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            issues.append(src.issue(path, f"missing required key {name!r}"))
    if len(issues) > n_before:
        return INVALID
    try:
        return cls(**kwargs)
    except FieldError as exc:
        issues.append(src.issue((*path, exc.field), str(exc)))
        return INVALID
    except (ValueError, TypeError) as exc:
        issues.append(src.issue(path, str(exc)))
        return INVALID


def parse(value: Any, cls: type, src: SourceMap, path: Path = ()) -> Any:
    """Convert ``value`` to ``cls`` or raise :class:`ConfigError` listing every issue."""
    issues: list[Issue] = []
    out = convert(value, cls, path, src, issues)
    if issues:
        raise ConfigError(issues)
    return out


def describe_schema(cls: type) -> list[tuple[str, str, str]]:
    """List ``(key, type, default)`` of a config dataclass, for ``unetyemu plugins`` and docs."""
    hints = get_type_hints(cls, include_extras=True)
    rows = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = repr(f.default_factory())
        else:
            default = "(required)"
        rows.append((f.name, _type_name(hints[f.name]), default))
    return rows


__all__ = [
    "ConfigError",
    "Each",
    "FieldError",
    "Ge",
    "Gt",
    "INVALID",
    "Issue",
    "Le",
    "Lt",
    "MaxLen",
    "NonEmpty",
    "Ordered",
    "SourceMap",
    "convert",
    "describe_schema",
    "format_path",
    "parse",
]
