"""Load YAML while remembering the line of every key, so that errors can point at the file.

PyYAML's ``safe_load`` forgets where values came from and silently keeps the last of two duplicate
keys. Here the document is composed into nodes, duplicate keys are reported, and each key path is
mapped to its 1-based line number in a :class:`~unetyemu_ecs.config.schema.SourceMap`.

Input is bounded before it is built (:func:`prescan`): the text's size, its nesting depth and the
number of nodes after alias expansion, so that neither an alias bomb ("billion laughs"), a
self-referencing anchor, thousands of nested brackets nor a device like ``/dev/zero`` can exhaust
memory, recursion or time. libyaml is used when PyYAML has it (about 15x faster).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path as FsPath
from typing import Any

import yaml

from .schema import ConfigError, Issue, Path, SourceMap

_Loader: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader) if yaml.__with_libyaml__ else yaml.SafeLoader


def prescan(text: str, source: str, *, max_depth: int, max_nodes: int, aliases: bool = True,
            what: str = "file") -> None:
    """Refuse deep nesting and too many nodes (counting each alias as the nodes it stands for).

    Reads parser events one by one and stops at the first offence, before anything is built:
    expanding aliases is exponential (a few lines can stand for billions of nodes), an alias inside
    its own anchor recurses forever, and PyYAML's scanner is quadratic in flow nesting.
    ``aliases=False`` refuses any alias (missions, which arrive over the network). Text that does
    not parse is left for the loader to report.

    Raises
    ------
    ConfigError
        Naming ``source`` and the line of the offending event.
    """
    def fail(event: yaml.Event, message: str) -> None:
        raise ConfigError([Issue(source, event.start_mark.line + 1, (), message)])

    open_anchors: list[str | None] = []   # anchor of each open collection
    sizes: list[int] = []                 # nodes (expanded) inside each open collection so far
    deepest: list[int] = []               # depth below each open collection
    anchors: dict[str, tuple[int, int]] = {}   # anchor -> (expanded nodes, depth below it)
    total = 0

    def add(n: int, below: int) -> None:
        nonlocal total
        total += n
        if sizes:
            sizes[-1] += n
            deepest[-1] = max(deepest[-1], below + 1)

    try:
        for event in yaml.parse(text, Loader=_Loader):
            if isinstance(event, yaml.AliasEvent):
                if not aliases:
                    fail(event, f"YAML anchors and aliases are not allowed in a {what}")
                if event.anchor in open_anchors:
                    fail(event, f"alias *{event.anchor} refers to its own anchor (a structure that contains itself)")
                n, below = anchors.get(event.anchor, (1, 0))
                if len(sizes) + below > max_depth:
                    fail(event, f"{what} is nested more than {max_depth} levels deep (through alias *{event.anchor})")
                add(n, below)
            elif isinstance(event, yaml.ScalarEvent):
                add(1, 0)
                if event.anchor is not None:
                    anchors[event.anchor] = (1, 0)
            elif isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
                if len(sizes) + 1 > max_depth:
                    fail(event, f"{what} is nested more than {max_depth} levels deep")
                total += 1
                open_anchors.append(event.anchor)
                sizes.append(1)
                deepest.append(0)
            elif isinstance(event, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
                anchor, n, below = open_anchors.pop(), sizes.pop(), deepest.pop()
                if anchor is not None:
                    anchors[anchor] = (n, below + 1)
                if sizes:
                    sizes[-1] += n
                    deepest[-1] = max(deepest[-1], below + 1)
            if total > max_nodes:
                fail(event, f"{what} has more than {max_nodes} values (after expanding aliases)")
    except yaml.YAMLError:
        # Text that does not parse is left for the loader, unless it fails for its nesting: libyaml (PyYAML
        # 6.0.4) refuses flow nesting beyond 1000 before it emits the first event, so look at the brackets
        line = _flow_nesting_line(text, max_depth)
        if line is not None:
            raise ConfigError([Issue(source, line, (), f"{what} is nested more than {max_depth} levels deep")]) from None
        return


def _flow_nesting_line(text: str, max_depth: int) -> int | None:
    """The line (1-based) where ``[``/``{`` brackets outside quoted strings first nest deeper than
    ``max_depth``, or None. Only for text the YAML parser refused (a plain scalar may hold a bracket)."""
    depth, line, quote, escaped = 0, 1, "", False
    for ch in text:
        if ch == "\n":
            line += 1
        if quote:
            if escaped:
                escaped = False
            elif ch == "\\" and quote == '"':
                escaped = True
            elif ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            if depth > max_depth:
                return line
        elif ch in "]}":
            depth = max(depth - 1, 0)
    return None


def _build(node: yaml.Node, path: Path, src: SourceMap, constructor: yaml.constructor.SafeConstructor,
           issues: list[Issue]) -> Any:
    src.lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = constructor.construct_object(key_node, deep=True)
            if not isinstance(key, (str, int)):
                issues.append(Issue(src.file, key_node.start_mark.line + 1, path,
                                    f"mapping keys must be strings, got {key!r}"))
                continue
            child = (*path, key)
            if key in out:
                issues.append(Issue(src.file, key_node.start_mark.line + 1, child,
                                    f"duplicate key {key!r} (first on line {src.lines[child]})"))
                continue
            src.lines[child] = key_node.start_mark.line + 1
            out[key] = _build(value_node, child, src, constructor, issues)
        return out
    if isinstance(node, yaml.SequenceNode):
        items = []
        for i, item in enumerate(node.value):
            src.lines[(*path, i)] = item.start_mark.line + 1
            items.append(_build(item, (*path, i), src, constructor, issues))
        return items
    return constructor.construct_object(node, deep=True)


def load_yaml_text(text: str, file: str) -> tuple[Any, SourceMap]:
    """Parse ``text``; return the plain document and its :class:`SourceMap`.

    Raises
    ------
    ConfigError
        On a YAML syntax error or duplicate keys, naming file and line.
    """
    src = SourceMap(file)
    try:
        node = yaml.compose(text, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        raise ConfigError([Issue(file, line, (), f"YAML syntax error: {exc.problem or exc}")]) from None
    except yaml.YAMLError as exc:
        raise ConfigError([Issue(file, None, (), f"YAML error: {exc}")]) from None
    if node is None:
        return {}, src
    issues: list[Issue] = []
    constructor = yaml.constructor.SafeConstructor()
    try:
        doc = _build(node, (), src, constructor, issues)
    except yaml.constructor.ConstructorError as exc:
        mark = exc.problem_mark
        raise ConfigError([Issue(file, mark.line + 1 if mark else None, (), str(exc.problem))]) from None
    except (ValueError, OverflowError) as exc:   # e.g. an integer of more than 4300 digits
        raise ConfigError([Issue(file, None, (), f"YAML value cannot be read: {exc}")]) from None
    if issues:
        raise ConfigError(issues)
    return doc, src


def read_text_file(path: str | FsPath, max_bytes: int, what: str = "file") -> str:
    """Read at most ``max_bytes`` of UTF-8 text from a regular file (or a character device such as
    ``/dev/null``, read without blocking); anything else, or anything longer, is a ConfigError."""
    p = FsPath(path)

    def fail(message: str) -> ConfigError:
        return ConfigError([Issue(str(p), None, (), message)])

    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise fail("file not found") from None
    except OSError as exc:
        raise fail(f"cannot read file: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISDIR(mode):
            raise fail("is a directory, not a file")
        if not (stat.S_ISREG(mode) or stat.S_ISCHR(mode)):
            kind = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a file"
            raise fail(f"is {kind}; a {what} must be a regular file")
        chunks, size = [], 0
        while size <= max_bytes:
            chunk = os.read(fd, max_bytes + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except BlockingIOError:
        raise fail(f"cannot read without waiting (a terminal or device?); a {what} must be a regular file") from None
    except OSError as exc:
        raise fail(f"cannot read file: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > max_bytes:
        raise fail(f"is larger than {max_bytes} bytes (the limit of a {what})")
    try:
        return b"".join(chunks).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise fail(f"is not UTF-8 text: {exc}") from None


def load_yaml_file(path: str | FsPath, max_bytes: int, *, max_depth: int, max_nodes: int,
                   what: str = "file") -> tuple[Any, SourceMap]:
    """Read (bounded: :func:`read_text_file`), prescan and parse a YAML file."""
    text = read_text_file(path, max_bytes, what)
    prescan(text, str(FsPath(path)), max_depth=max_depth, max_nodes=max_nodes, what=what)
    return load_yaml_text(text, str(FsPath(path)))
