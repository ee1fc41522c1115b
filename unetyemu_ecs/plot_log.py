"""Read a vehicle CSV log for plotting, keeping every readable row and saying what was skipped.

A log written by ``TrajectoryLogSystem`` (``systems/outputs.py``) is flushed row by row, so a run
killed with SIGKILL leaves a last line without its newline, and a disk fault or a stray write can
leave bytes that are not text. Neither may stop the rest of the log from being plotted: each line is
decoded and checked on its own, and every line that is left out is named with its number and why.
"""

from __future__ import annotations

import csv
import math
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

TEXT_COLUMNS = frozenset({"mode", "nav_state", "landed_state", "mission_step_type", "drive_mode"})   # every other column is a number
MAX_LOG_BYTES = 512 * 1024**2    # a 10 Hz log of one vehicle grows by ~10 MB per simulated hour
MAX_HEADER_BYTES = 64 * 1024
MAX_LISTED_LINES = 12            # line numbers named per reason before "and N more"


class LogError(ValueError):
    """A whole file cannot be read as a vehicle log (the message says why)."""


@dataclass
class LogTable:
    """The readable rows of one vehicle log.

    Attributes
    ----------
    path : the CSV file.
    columns : column name -> (M,) float64 array (numeric columns; non-finite values are NaN)
        or (M,) object array of str (``TEXT_COLUMNS``), one entry per kept row.
    lines : (M,) int array, the 1-based line number in the file of each kept row.
    notes : one sentence per kind of problem found, naming the lines or columns concerned.
    """

    path: Path
    columns: dict[str, np.ndarray]
    lines: np.ndarray
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.lines.size)

    def has(self, *names: str) -> bool:
        """Return whether every column in ``names`` is in the log."""
        return all(n in self.columns for n in names)


def line_ranges(numbers: list[int]) -> str:
    """Format sorted line numbers compactly: ``3, 7-9, 12`` (at most ``MAX_LISTED_LINES`` ranges)."""
    ranges: list[tuple[int, int]] = []
    for n in numbers:
        if ranges and n == ranges[-1][1] + 1:
            ranges[-1] = (ranges[-1][0], n)
        else:
            ranges.append((n, n))
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in ranges[:MAX_LISTED_LINES])
    if len(ranges) > MAX_LISTED_LINES:
        text += f" and {sum(b - a + 1 for a, b in ranges[MAX_LISTED_LINES:])} more"
    return text


def _parse_number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def read_log(path: Path) -> LogTable:
    """Read the rows of ``path`` that are complete and well formed, one line at a time.

    Raises
    ------
    LogError
        If the file cannot be opened, is empty or too large, or its first line is not a log header
        (a CSV line with a ``time_s`` column). A file with a header but no usable row is returned
        with zero rows and a note.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_LOG_BYTES:
            raise LogError(f"{path}: {size / 1024**2:.0f} MiB is more than the {MAX_LOG_BYTES / 1024**2:.0f} MiB "
                           "a vehicle log can plausibly reach; not read")
        with open(path, "rb") as fh:
            return _read_lines(path, fh)
    except OSError as exc:
        raise LogError(f"{path}: cannot read ({exc.strerror or exc})") from None


def _read_lines(path: Path, fh) -> LogTable:
    first = fh.readline(MAX_HEADER_BYTES)
    if not first:
        raise LogError(f"{path}: empty file")
    header = _decode_header(path, first)
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise LogError(f"{path}:1: header repeats column(s) {', '.join(dup)}")
    n_cols = len(header)
    text_idx = [j for j, h in enumerate(header) if h in TEXT_COLUMNS]
    num_idx = [j for j, h in enumerate(header) if h not in TEXT_COLUMNS]
    t_idx = header.index("time_s")
    skipped: dict[str, list[int]] = {}
    numbers = array("d")                      # kept rows x num_idx, row-major
    texts: list[list[str]] = [[] for _ in text_idx]
    kept_lines = array("q")
    n_lines = 1
    for lineno, chunk in enumerate(fh, start=2):
        n_lines = lineno
        reason = None
        if not chunk.endswith(b"\n"):         # only the last line can lack its row end
            reason = "the last line is incomplete (no line end: the run was probably killed while writing it)"
        else:
            try:
                text = chunk.rstrip(b"\r\n").decode("utf-8")
            except UnicodeDecodeError:
                reason = "not UTF-8 text"
            else:
                reason, fields, row = _check_row(text, n_cols, num_idx, t_idx)
        if reason is not None:
            skipped.setdefault(reason, []).append(lineno)
            continue
        numbers.extend(row)
        for k, j in enumerate(text_idx):
            texts[k].append(fields[j])
        kept_lines.append(lineno)
    notes = [f"{path}: skipped line{'s' if len(nums) > 1 else ''} {line_ranges(nums)}: {why}"
             for why, nums in skipped.items()]
    lines = np.frombuffer(kept_lines, dtype=np.int64).copy() if kept_lines else np.empty(0, dtype=np.int64)
    table = np.frombuffer(numbers, dtype=np.float64).reshape(lines.size, len(num_idx)) if numbers else \
        np.empty((lines.size, len(num_idx)))
    columns: dict[str, np.ndarray] = {}
    for k, j in enumerate(num_idx):
        values = table[:, k].copy()
        bad = ~np.isfinite(values)
        if bad.any():
            notes.append(f"{path}: column {header[j]}: non-finite value on line{'s' if bad.sum() > 1 else ''} "
                         f"{line_ranges([int(n) for n in lines[bad]])}, not drawn")
            values[bad] = np.nan
        columns[header[j]] = values
    for k, j in enumerate(text_idx):
        columns[header[j]] = np.array(texts[k], dtype=object)
    if lines.size == 0:
        notes.append(f"{path}: no usable data rows" + ("" if n_lines > 1 else " (header only)"))
    return LogTable(path=path, columns=columns, lines=lines, notes=notes)


def _check_row(text: str, n_cols: int, num_idx: list[int],
               t_idx: int) -> tuple[str | None, list[str], list[float]]:
    """Return (why the line is unusable or None, its fields, its numbers in ``num_idx`` order)."""
    if not text.strip():
        return "blank", [], []
    if "\0" in text:
        return "contains NUL bytes", [], []
    fields = next(csv.reader([text]), [])
    if len(fields) != n_cols:
        return f"wrong number of fields (expected {n_cols})", [], []
    row = [_parse_number(fields[j]) for j in num_idx]
    if any(v is None for v in row):
        return "a numeric column holds something that is not a number", [], []
    if not math.isfinite(float(fields[t_idx])):
        return "time_s is not a finite number", [], []
    return None, fields, row


def _decode_header(path: Path, chunk: bytes) -> list[str]:
    try:
        text = chunk.rstrip(b"\r\n").decode("utf-8-sig")      # -sig: a spreadsheet may have added a BOM
    except UnicodeDecodeError:
        raise LogError(f"{path}:1: not UTF-8 text, so not a vehicle log") from None
    fields = [f.strip() for f in next(csv.reader([text.replace("\0", "")]), [])]
    if "\0" in text or "time_s" not in fields:
        raise LogError(f"{path}:1: not a vehicle log header (a CSV line naming a time_s column)")
    return fields


__all__ = ["LogError", "LogTable", "MAX_LOG_BYTES", "TEXT_COLUMNS", "line_ranges", "read_log"]
