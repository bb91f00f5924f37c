"""Child processes that die with the service: a solver worker or a model checker must not
keep solving (or parsing) after the service that started it has died.

:func:`die_with_parent`, called first thing in a child process, asks Linux to SIGKILL the
child when its parent goes (``prctl(PR_SET_PDEATHSIG)``; the parent *thread* that started
the child, in Linux's terms: the service starts its children from threads that live as long
as it does), and starts a watchdog thread that exits the process when it has been
re-parented (``os.getppid()`` changed: the parent died before the ``prctl``, or on a system
without it). Either way a child outlives its service by at most
:data:`WATCH_INTERVAL` seconds (plus the time its solve holds the interpreter, for the
watchdog).
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

__all__ = ["WATCH_INTERVAL", "PipedChild", "die_with_parent", "received"]

#: How often the watchdog looks at the parent [s].
WATCH_INTERVAL = 0.25
_PR_SET_PDEATHSIG = 1


def _pdeathsig() -> bool:
    """SIGKILL this process when its parent dies (Linux); whether it was set."""
    with contextlib.suppress(Exception):
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return int(libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)) == 0
    return False


def die_with_parent(parent_pid: int | None = None, pdeathsig: bool = True) -> None:
    """Make this (child) process end when its parent process does (see the module).
    ``pdeathsig=False`` for a child started from a thread that may end before the
    service does (an API thread-pool thread: Linux would kill the child with it); the
    watchdog alone then ends it."""
    parent = os.getppid() if parent_pid is None else parent_pid
    if pdeathsig:
        _pdeathsig()
    if os.getppid() != parent:  # the parent died before the prctl
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(WATCH_INTERVAL)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="dexroll-lifeline", daemon=True).start()


class PipedChild:
    """A daemon child process of the context ``ctx`` running ``target(conn, *args)``,
    ``conn`` its end of a pipe whose other end is :attr:`conn` (the child's end closed
    here once it has started); :meth:`kill` ends it, whatever state it is in."""

    def __init__(self, ctx: Any, target: Callable[..., None], name: str, *args: Any) -> None:
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=target, name=name, daemon=True,
                                   args=(child, *args))
        self.process.start()
        child.close()

    def kill(self) -> None:
        with contextlib.suppress(Exception):
            self.process.kill()
            self.process.join(timeout=5)
            self.conn.close()


def received(conn: Any) -> Iterator[Any]:
    """The messages a child process receives on ``conn``, until its pipe closes or a
    None (stop) arrives."""
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        if msg is None:
            return
        yield msg
