"""A Ray cluster of this machine's own processes, for tests, benchmarks and trying the Ray
executor out: a head and more nodes started with ``ray start`` on loopback, each with its
CPUs and a resource named after it, all in one temporary folder by which its processes are
found (and killed: a node alone, to see a node lost, or all of them).

Ray 2.60 starts a head with token authentication: every process of the cluster and its
clients (the service's bridge) run with ``RAY_AUTH_MODE=token`` (:attr:`LocalRayCluster.env`)
and read the token the head wrote to ``~/.ray/auth_token``.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["LocalRayCluster", "descendants"]

#: The environment of the cluster's processes and of its clients.
RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_DISABLE_IMPORT_WARNING": "1"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _processes() -> dict[int, tuple[int, str]]:
    """pid -> (parent pid, command line) of every process."""
    out = subprocess.run(["ps", "-ww", "-eo", "pid,ppid,args"], capture_output=True,
                         text=True).stdout
    procs = {}
    for line in out.splitlines()[1:]:
        pid, ppid, *args = line.split(maxsplit=2)
        procs[int(pid)] = (int(ppid), args[0] if args else "")
    return procs


def descendants(pid: int) -> set[int]:
    """The processes started by ``pid`` (a raylet's workers and agents), at any depth."""
    parent = {p: pp for p, (pp, _) in _processes().items()}
    found: set[int] = set()
    for child in parent:
        p = child
        while p in parent and p > 1:
            p = parent[p]
            if p == pid:
                found.add(child)
                break
    return found


#: How many times a cluster is started afresh when ``ray start`` fails.
START_ATTEMPTS = 2


class LocalRayCluster:
    """A head with ``head_cpus`` and one node per entry of ``node_cpus`` (resources
    ``node1``, ``node2``, ...), started at once; :meth:`stop` ends them all."""

    def __init__(self, head_cpus: int = 1, node_cpus: tuple[int, ...] = (1,)) -> None:
        self.env = {**os.environ, **RAY_ENV}
        self.nodes = [f"node{i + 1}" for i in range(len(node_cpus))]
        for attempt in range(START_ATTEMPTS):
            self.temp = Path(tempfile.mkdtemp(prefix="dxr-", dir="/tmp"))  # short: sockets
            self.port = _free_port()
            self.address = f"127.0.0.1:{self.port}"
            try:
                self._ray("start", "--head", f"--port={self.port}",
                          f"--num-cpus={head_cpus}", "--include-dashboard=false",
                          "--disable-usage-stats")
                for name, cpus in zip(self.nodes, node_cpus, strict=True):
                    self._ray("start", f"--address={self.address}", f"--num-cpus={cpus}",
                              f'--resources={{"{name}": 1}}')
                break
            except subprocess.CalledProcessError:
                # (under load `ray start` can give up on its own processes' start: the
                # full suite beside a benchmark on 2 cores, 2026-12-06) again, afresh
                self.stop()
                if attempt + 1 == START_ATTEMPTS:
                    raise
            except BaseException:
                self.stop()
                raise

    def _ray(self, *args: str) -> None:
        ray = Path(sys.executable).with_name("ray")
        try:
            subprocess.run([str(ray), *args, f"--temp-dir={self.temp}"], env=self.env,
                           check=True, capture_output=True, timeout=120)
        except subprocess.CalledProcessError as exc:  # say what ray said
            exc.add_note((exc.stderr or b"").decode(errors="replace")[-2000:])
            raise

    def raylets(self) -> dict[int, str]:
        """pid -> command line of this cluster's raylets (one per node)."""
        return {pid: args for pid, (_, args) in _processes().items()
                if "raylet/raylet" in args and str(self.temp) in args}

    def raylet(self, node: str) -> int:
        """The raylet of ``node`` (a name of :attr:`nodes`)."""
        for pid, args in self.raylets().items():
            if re.search(rf"\b{re.escape(node)}\b", args):
                return pid
        raise LookupError(f"no raylet of {node} among {list(self.raylets())}")

    def node_of(self, pid: int) -> int | None:
        """The raylet whose node runs the process ``pid`` (None: none of this cluster's)."""
        return next((r for r in self.raylets() if pid in descendants(r)), None)

    def daemon_cpu(self) -> float:
        """CPU seconds used so far by the cluster's own processes (GCS, raylets, agents,
        idle workers): everything of it but the actors' processes (``ray::_Host...``)."""
        procs = _processes()
        own = {pid for pid, (_, args) in procs.items() if str(self.temp) in args}
        total = 0.0
        for pid in own | set().union(*(descendants(p) for p in own)):
            if procs.get(pid, (0, ""))[1].startswith("ray::_Host"):
                continue
            with contextlib.suppress(OSError, IndexError, ValueError):
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        return total

    def kill_node(self, node: str) -> None:
        """SIGKILL ``node``'s raylet and what it started: the node is lost, as if its
        machine went away."""
        raylet = self.raylet(node)
        for pid in {raylet} | descendants(raylet):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)

    def stop(self) -> None:
        """SIGKILL every process of the cluster and all they started."""
        own = {pid for pid, (_, args) in _processes().items() if str(self.temp) in args}
        for pid in own | set().union(*(descendants(p) for p in own)):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        time.sleep(0.5)
        shutil.rmtree(self.temp, ignore_errors=True)
