"""The Dockerfile runs the README's steps (the Makefile targets CI exercises).

There is no Docker engine here: these tests check that the image is built with the same
targets `make run` uses, and run the image's health check command for real.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from conftest import Server

ROOT = Path(__file__).resolve().parents[1]
DOCKERFILE = (ROOT / "Dockerfile").read_text()


def instructions(keyword: str) -> list[str]:
    text = DOCKERFILE.replace("\\\n", " ")
    return [line.split(None, 1)[1].strip() for line in text.splitlines()
            if line.strip().startswith(keyword + " ")]


def dry_run(target: str) -> str:
    """The commands `make TARGET` would run from scratch (nothing is executed)."""
    env = {k: v for k, v in os.environ.items() if k not in ("MAKELEVEL", "MAKEFLAGS", "MFLAGS")}
    proc = subprocess.run(["make", "--no-print-directory", "-n", "-B", target], cwd=ROOT,
                          env=env, capture_output=True, text=True, check=True)
    return proc.stdout


def test_image_is_slim_non_root_and_healthchecked() -> None:
    assert instructions("FROM")[0].startswith("python:3.11-slim")
    users = instructions("USER")
    assert users and users[-1] not in ("root", "0")
    assert DOCKERFILE.index("USER") < DOCKERFILE.index("CMD")
    assert "/healthz" in instructions("HEALTHCHECK")[0]


def test_image_builds_with_the_targets_make_run_uses() -> None:
    runs = instructions("RUN")
    assert "make deps" in runs and "make install" in runs
    assert runs.index("make deps") < runs.index("make install")
    # dependencies get their own layer: copied before the sources
    assert DOCKERFILE.index("RUN make deps") < DOCKERFILE.index("COPY --chown=dexroll:dexroll . .")
    run = dry_run("run")
    install = dry_run("install")
    deps = dry_run("deps")
    assert deps.strip() and deps.strip() in install and install.strip() in run
    # the image's command is the command `make run` ends with
    cmd = json.loads(instructions("CMD")[0])
    last = run.strip().splitlines()[-1].split()  # .venv/bin/dexroll serve
    assert cmd[-1] == last[-1] == "serve"
    assert cmd[0] == "/app/" + last[0]  # WORKDIR /app


def test_healthcheck_command_passes_against_a_live_service(live_server: Server) -> None:
    exec_form = json.loads(instructions("HEALTHCHECK")[0].split("CMD", 1)[1])
    port = re.search(r":(\d+)$", live_server.url)
    assert port is not None
    env = {**os.environ, "DEXROLL_PORT": port.group(1)}
    proc = subprocess.run([sys.executable, *exec_form[1:]], env=env, capture_output=True,
                          text=True, timeout=30, check=False)
    assert proc.returncode == 0, proc.stderr
    env["DEXROLL_PORT"] = "1"  # nothing listens there: the check must fail
    bad = subprocess.run([sys.executable, *exec_form[1:]], env=env, capture_output=True,
                         text=True, timeout=30, check=False)
    assert bad.returncode != 0
