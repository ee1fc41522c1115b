"""Load YAML while remembering the line of every key, so that errors can point at the file.

PyYAML's ``safe_load`` forgets where values came from and silently keeps the last of two duplicate
keys. Here the document is composed into nodes, duplicate keys are reported, and each key path is
mapped to its 1-based line number in a :class:`~unetyemu_ecs.config.schema.SourceMap`.
"""

from __future__ import annotations

from pathlib import Path as FsPath
from typing import Any

import yaml

from .schema import ConfigError, Issue, Path, SourceMap


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
        node = yaml.compose(text, Loader=yaml.SafeLoader)
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
    if issues:
        raise ConfigError(issues)
    return doc, src


def load_yaml_file(path: str | FsPath) -> tuple[Any, SourceMap]:
    """Read and parse a YAML file; a missing or unreadable file is a :class:`ConfigError`."""
    p = FsPath(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError([Issue(str(p), None, (), "file not found")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError([Issue(str(p), None, (), f"cannot read file: {exc}")]) from None
    return load_yaml_text(text, str(p))
