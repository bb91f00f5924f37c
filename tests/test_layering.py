"""The optimisation core never depends on the web service (data flows one way)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

OCP = Path(__file__).resolve().parents[1] / "ocp"


def test_ocp_sources_never_import_planner_service() -> None:
    offenders = []
    for path in OCP.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            offenders += [f"{path.name}: {n}" for n in names if n.split(".")[0] in
                          ("planner_service", "fastapi", "uvicorn", "pydantic")]
    assert not offenders


def test_importing_ocp_loads_no_service_module() -> None:
    code = ("import sys, ocp.ball_on_palm, ocp.contact, ocp.surfaces, ocp.collocation;"
            "bad = [m for m in sys.modules if m.split('.')[0] in "
            "('planner_service', 'fastapi', 'uvicorn')]; print(bad); sys.exit(bool(bad))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_wire_statuses_and_limits_match_the_core() -> None:
    """The core and the wire contract cannot import each other; their shared vocabulary
    (plan statuses, request limits) is pinned here instead."""
    import dexroll_client.models as wire
    import ocp.problem as core
    from ocp.solution import Status

    assert {s.value for s in Status} == {s.value for s in wire.PlanStatus}
    for name in ("MAX_INTERVALS", "MAX_VIA_POINTS", "MAX_POSITION", "MAX_DURATION"):
        assert getattr(core, name) == getattr(wire, name), name
