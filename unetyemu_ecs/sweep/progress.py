"""Progress of a sweep: finished, running and failed runs with an ETA, on one live line (a terminal) or
a line every ``every_s`` seconds (a log file, CI)."""

from __future__ import annotations

import time
from typing import TextIO


def eta_s(done: int, remaining: int, running: int, elapsed_s: float) -> float | None:
    """Seconds until every run is finished at the pace so far, ``done / elapsed_s`` runs per second with
    the workers busy (None before the first run ends); the runs under way count as half done."""
    if done <= 0 or elapsed_s <= 0:
        return None
    return (remaining + 0.5 * running) * elapsed_s / done


def _clock(seconds: float | None) -> str:
    if seconds is None:
        return "--:--"
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m:02d}:{s:02d}"


class SweepProgress:
    """Call :meth:`update` whenever counts change (and now and then); :meth:`done` ends the line."""

    def __init__(self, stream: TextIO, total: int, skipped: int = 0, every_s: float = 10.0) -> None:
        self.stream = stream
        self.total = total
        self.skipped = skipped
        self.every_s = every_s
        self.tty = stream.isatty()
        self.t0 = time.monotonic()
        self._last = -every_s
        self._last_line = ""

    def line(self, finished: int, running: int, failed: int) -> str:
        """``[#####...] 12/40 finished, 2 running, 1 failed | 03:10 elapsed, ETA 04:55``"""
        elapsed = time.monotonic() - self.t0
        ended = finished + failed
        remaining = self.total - self.skipped - ended - running
        frac = (ended + self.skipped) / self.total if self.total else 1.0
        bar = "#" * int(round(frac * 24))
        eta = eta_s(ended, remaining, running, elapsed)
        skipped = f" ({self.skipped} from before)" if self.skipped else ""
        return (f"[{bar:<24}] {finished + self.skipped}/{self.total} finished{skipped}, {running} running, "
                f"{failed} failed | {_clock(elapsed)} elapsed, ETA {_clock(eta) if remaining + running else '00:00'}")

    def update(self, finished: int, running: int, failed: int, force: bool = False) -> None:
        text = self.line(finished, running, failed)
        now = time.monotonic()
        if self.tty:
            self.stream.write("\r" + text.ljust(len(self._last_line)))
            self.stream.flush()
        elif now - self._last >= self.every_s or (force and text != self._last_line):
            self.stream.write(text + "\n")
            self.stream.flush()
            self._last = now
        self._last_line = text

    def note(self, text: str) -> None:
        """A message between progress lines (a run that failed)."""
        if self.tty and self._last_line:
            self.stream.write("\r" + " " * len(self._last_line) + "\r")
        self.stream.write(text + "\n")
        self.stream.flush()
        if self.tty and self._last_line:
            self.stream.write(self._last_line)
            self.stream.flush()

    def done(self) -> None:
        if self.tty and self._last_line:
            self.stream.write("\n")
            self.stream.flush()


__all__ = ["SweepProgress", "eta_s"]
