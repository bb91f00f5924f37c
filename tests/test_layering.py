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


# -- the service's own layers ----------------------------------------------------------------
#
# planner_service.planners (the adapters: the only door to ocp) <- planner_service.jobs (store,
# workers) <- planner_service.api (HTTP); cli, warmup and settings sit beside them. Imports
# only point down that chain.

SERVICE = Path(__file__).resolve().parents[1] / "planner_service"


def _imports(path: Path) -> set[str]:
    """The absolute names of the modules a source file imports (relative ones resolved)."""
    package = ".".join(path.relative_to(SERVICE.parent).with_suffix("").parts[:-1])
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
                found.add(module)
                found.update(f"{module}.{a.name}" for a in node.names)
            elif node.module:
                found.add(node.module)
    return found


def _offenders(folder: str, forbidden: tuple[str, ...]) -> list[str]:
    root = SERVICE / folder if folder else SERVICE
    files = root.rglob("*.py") if folder else root.glob("*.py")
    return [f"{p.relative_to(SERVICE)}: {m}" for p in files for m in sorted(_imports(p))
            if any(m == f or m.startswith(f + ".") for f in forbidden)]


def test_the_import_resolver_sees_relative_imports() -> None:
    found = _imports(SERVICE / "api" / "deps.py")
    assert "planner_service.jobs.store" in found and "planner_service.planners.fields" in found


def test_planners_import_neither_jobs_nor_the_api() -> None:
    assert not _offenders("planners", ("planner_service.api", "planner_service.jobs",
                                       "planner_service.cli", "planner_service.warmup",
                                       "planner_service.convert", "fastapi", "starlette"))


def test_jobs_do_not_import_the_api() -> None:
    assert not _offenders("jobs", ("planner_service.api", "planner_service.cli", "fastapi",
                                   "starlette"))


def test_only_the_planners_touch_the_core() -> None:
    """The core's (ocp) types stay inside planner_service.planners: the API, the jobs, the
    command line and the warm-up reach the core through the planners' adapters."""
    offenders = _offenders("api", ("ocp",)) + _offenders("jobs", ("ocp",)) \
        + _offenders("", ("ocp",))
    assert not offenders
