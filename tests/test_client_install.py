"""The client installs on its own, with httpx and pydantic only (no CasADi, Pinocchio,
FastAPI, NumPy), into a fresh virtual environment, and talks to a live service there."""

from __future__ import annotations

import subprocess
import sys
import tomllib
import venv
from pathlib import Path

from conftest import Server

ROOT = Path(__file__).resolve().parents[1]
CLIENT = ROOT / "clients" / "python"


def test_client_declares_only_httpx_and_pydantic() -> None:
    deps = tomllib.loads((CLIENT / "pyproject.toml").read_text())["project"]["dependencies"]
    names = {d.split(">")[0].split("<")[0].split("=")[0].split("[")[0].strip() for d in deps}
    assert names == {"httpx", "pydantic"}


def test_client_installs_alone_and_plans_against_a_live_service(tmp_path: Path,
                                                                live_server: Server) -> None:
    # a fresh environment without pip of its own (seeding pip into it took ~8 s of CPU):
    # this interpreter's pip installs into it and lists it (``pip --python``)
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", str(python),
           "--disable-pip-version-check"]
    install = subprocess.run([*pip, "install", "--quiet", str(CLIENT)],
                             capture_output=True, text=True, timeout=600, check=False)
    assert install.returncode == 0, install.stdout + install.stderr
    listed = subprocess.run([*pip, "list", "--format=freeze"],
                            capture_output=True, text=True, check=True).stdout.lower()
    assert "dexroll-client==" in listed and "httpx==" in listed and "pydantic==" in listed
    assert "pip==" not in listed  # the environment's own packages, not this one's
    for heavy in ("casadi", "pin==", "fastapi", "numpy", "uvicorn"):
        assert heavy not in listed, f"{heavy} was installed with the client"
    code = f"""
import sys
from dexroll_client import DexrollClient, JobState
with DexrollClient.from_url({live_server.url!r}) as client:
    job = client.plan({{"initial": {{"x": 0, "y": 0, "u": 0, "v": 0, "psi": 0}},
                       "goal": {{"x": 0.02}}, "duration": 1.0}}, timeout=120)
assert job.state is JobState.SUCCEEDED, job
assert job.result.certificate.passed
print("ok")
"""
    run = subprocess.run([str(python), "-c", code], capture_output=True, text=True,
                         timeout=300, check=False, cwd=tmp_path)
    assert run.returncode == 0 and "ok" in run.stdout, run.stdout + run.stderr
