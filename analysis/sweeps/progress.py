"""Progress on stderr: one updating line per phase on a terminal, a few plain lines otherwise.

On a terminal the line is rewritten in place (carriage return) and ends when the phase closes; when
stderr is a file or a pipe (CI logs) only the start of a phase and each quarter of its work are
printed, so that a log stays short and the summary printed after it is not scrolled away.
"""
from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    """Progress of one named phase of ``total`` steps.

    Parameters
    ----------
    phase : what is being done, e.g. ``"Tables 2-3 sweep"``; starts every line.
    total : number of steps.
    enabled : False prints nothing.
    unit : name of a step (``"formulations"``, ``"trials"``).
    checkpoints : lines between start and end when stderr is not a terminal (4: each quarter; 0: only
        the closing line, for the many short batches of one phase).
    """

    def __init__(self, phase: str, total: int, enabled: bool = True, unit: str = "", stream=None,
                 checkpoints: int = 4):
        self.phase, self.total, self.unit, self.checkpoints = phase, total, unit, checkpoints
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled and total > 0
        self.tty = self.enabled and getattr(self.stream, "isatty", lambda: False)()
        self.done = 0
        self.started = time.perf_counter()
        self._next_quarter = 1
        self._width = 0
        if self.enabled and not self.tty and checkpoints:
            self._line(f"{self.phase}: {self.total} {self.unit}".rstrip())

    def _line(self, text: str) -> None:
        print(text, file=self.stream, flush=True)

    def update(self, k: int = 1, detail: str = "") -> None:
        self.done += k
        if not self.enabled:
            return
        text = f"{self.phase}: {self.done}/{self.total} {self.unit}".rstrip() + (f"  {detail}" if detail else "")
        if self.tty:
            text = text[:150]
            print("\r" + text.ljust(self._width), end="", file=self.stream, flush=True)
            self._width = len(text)
        elif self.checkpoints and self.done * self.checkpoints >= self._next_quarter * self.total:
            while self.done * self.checkpoints >= self._next_quarter * self.total:
                self._next_quarter += 1
            if self.done < self.total:
                self._line(text)

    def close(self) -> None:
        if not self.enabled:
            return
        seconds = time.perf_counter() - self.started
        text = f"{self.phase}: {self.done}/{self.total} {self.unit} done in {seconds:.1f} s".replace("  ", " ")
        if self.tty:
            print("\r" + text.ljust(self._width), file=self.stream, flush=True)
        else:
            self._line(text)
        self.enabled = False
