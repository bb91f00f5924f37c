"""A progress bar on stderr: redrawn in place on a terminal, one line per finished unit
elsewhere (a CI log)."""

from __future__ import annotations

import shutil
import sys
import threading
import time
from collections.abc import Mapping
from typing import Any, TextIO

__all__ = ["Progress"]


def _clock(seconds: float) -> str:
    s = round(seconds)
    return f"{s // 60}:{s % 60:02d}"


class Progress:
    """Counts finished units; ``update(row)`` after each. Thread-safe."""

    def __init__(self, total: int, stream: TextIO | None = None, enabled: bool = True,
                 width: int = 30) -> None:
        self.total = total
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.width = width
        self.done = 0
        self.ok = 0
        self.start = time.perf_counter()
        self._lock = threading.Lock()
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def update(self, row: Mapping[str, Any]) -> None:
        with self._lock:
            self.done += 1
            self.ok += bool(row.get("ok"))
            if not self.enabled:
                return
            elapsed = time.perf_counter() - self.start
            eta = elapsed / self.done * (self.total - self.done) if self.done else 0.0
            what = (f"{row.get('problem_id')} {row.get('method')}: {row.get('status')}"
                    + ("" if row.get("ok") or row.get("status") != "solved"
                       else " (certificate failed)"))
            counts = f"{self.done}/{self.total}, {self.ok} ok"
            if self._tty:
                filled = int(self.width * self.done / max(self.total, 1))
                bar = "#" * filled + "-" * (self.width - filled)
                line = (f"\r[{bar}] {counts}, {_clock(elapsed)} elapsed, ~{_clock(eta)} left "
                        f"| {what}")
                columns = max(40, shutil.get_terminal_size((100, 20)).columns - 1)
                self.stream.write(line[:columns + 1].ljust(columns + 1))
                if self.done == self.total:
                    self.stream.write("\n")
            else:
                self.stream.write(f"[{counts}, {_clock(elapsed)}] {what}\n")
            self.stream.flush()
