"""Fixtures: real dexroll services (uvicorn, worker processes, SQLite) on loopback ports."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
from hypothesis import settings

STARTUP_TIMEOUT = 120.0  # s: spawned workers import CasADi before the service is ready

# The property tests draw the same examples on every run (derived from each test, no
# example database): a red CI run is the code's, not the draw's. Their settings in each
# file (examples, deadline) are made on top of this profile.
settings.register_profile("dexroll", derandomize=True, database=None)
settings.load_profile("dexroll")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Server:
    """A running `dexroll serve` process."""

    url: str
    data_dir: Path
    process: subprocess.Popen[bytes]
    log: Path

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=10)

    def log_text(self) -> str:
        return self.log.read_text(errors="replace")


def start_server(data_dir: Path, **env: str) -> Server:
    """Start the service as a real process and wait until /readyz answers 200."""
    port = free_port()
    data_dir.mkdir(parents=True, exist_ok=True)
    log = data_dir / f"server-{port}.log"
    environ = {**os.environ, "DEXROLL_HOST": "127.0.0.1", "DEXROLL_PORT": str(port),
               "DEXROLL_DATA_DIR": str(data_dir), "DEXROLL_WORKERS": "2",
               "DEXROLL_KILL_GRACE": "2", "DEXROLL_WARMUP": "", **env}
    with log.open("wb") as out:
        proc = subprocess.Popen([sys.executable, "-m", "planner_service.cli", "serve"],
                                env=environ, stdout=out, stderr=subprocess.STDOUT)
    server = Server(f"http://127.0.0.1:{port}", data_dir, proc, log)
    deadline = time.monotonic() + STARTUP_TIMEOUT
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the service exited at start:\n{server.log_text()}")
        try:
            if httpx.get(f"{server.url}/readyz", timeout=2).status_code == 200:
                return server
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    server.stop()
    raise RuntimeError(f"the service was not ready in {STARTUP_TIMEOUT} s:\n"
                       f"{server.log_text()}")


@pytest.fixture(scope="session")
def live_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    """One service shared by the tests that only need a healthy one (2 workers)."""
    server = start_server(tmp_path_factory.mktemp("live"))
    yield server
    server.stop()


@pytest.fixture
def server_factory(tmp_path: Path) -> Iterator[Callable[..., Server]]:
    """Start services of one's own (a fresh data folder each unless given); all stopped
    at the end of the test."""
    started: list[Server] = []

    def factory(data_dir: Path | None = None, **env: str) -> Server:
        server = start_server(data_dir or tmp_path / f"data{len(started)}", **env)
        started.append(server)
        return server

    yield factory
    for server in started:
        server.stop()


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, Path]:
    """The whole quick suite through the library, 2 workers, by the command line (the
    process pool's rows: tests/test_bench.py checks them, and compares a one-worker run, a
    live service's and Ray's with them)."""
    from planner_service import cli

    out = tmp_path_factory.mktemp("bench") / "quick"
    code = cli.main(["bench", "quick", "--workers", "2", "--out", str(out), "--no-progress"])
    return code, out


@dataclass
class CliPlan:
    """`dexroll plan <request> -o <result>` run as a real process."""

    request_file: Path
    proc: subprocess.CompletedProcess[str]
    result_file: Path


class CliPlans(dict[Path, CliPlan]):
    """Each request file planned by the command line when first asked for, in a folder of
    its own (its working directory): tests/test_cli.py checks the command line's output
    and result, tests/test_sim.py executes the same plans in MuJoCo (one plan of each
    example for the session)."""

    def __init__(self, folder: Path) -> None:
        super().__init__()
        self.folder = folder

    def __missing__(self, request_file: Path) -> CliPlan:
        cwd = self.folder / f"{request_file.stem}-{len(self)}"
        cwd.mkdir(parents=True)
        out = cwd / "result.json"
        proc = subprocess.run([sys.executable, "-m", "planner_service.cli", "plan",
                               str(request_file), "-o", str(out)], cwd=cwd,
                              capture_output=True, text=True, timeout=600, check=False)
        self[request_file] = CliPlan(request_file, proc, out)
        return self[request_file]


@pytest.fixture(scope="session")
def cli_plans(tmp_path_factory: pytest.TempPathFactory) -> CliPlans:
    return CliPlans(tmp_path_factory.mktemp("cli-plans"))
