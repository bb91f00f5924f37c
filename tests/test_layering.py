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
    code = ("import sys, ocp.ball_on_palm, ocp.geometry.contact, ocp.geometry.surfaces, "
            "ocp.transcription.collocation;"
            "bad = [m for m in sys.modules if m.split('.')[0] in "
            "('planner_service', 'fastapi', 'uvicorn')]; print(bad); sys.exit(bool(bad))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_wire_statuses_and_limits_match_the_core() -> None:
    """The core and the wire contract cannot import each other; their shared vocabulary
    (plan statuses, request limits) is pinned here instead."""
    import dexroll_client.models as wire
    import ocp.spec.problem as core
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
                                       "fastapi", "starlette"))


def test_jobs_do_not_import_the_api() -> None:
    assert not _offenders("jobs", ("planner_service.api", "planner_service.cli", "fastapi",
                                   "starlette"))


def test_only_the_planners_touch_the_core() -> None:
    """The core's (ocp) types stay inside planner_service.planners: the API, the jobs, the
    command line and the warm-up reach the core through the planners' adapters."""
    offenders = _offenders("api", ("ocp",)) + _offenders("jobs", ("ocp",)) \
        + _offenders("", ("ocp",))
    assert not offenders


# -- the core's own layers -------------------------------------------------------------------
#
# The data flow in the folder names: geometry (surfaces, contact kinematics, rotations,
# grasp geometry) and robots (fingers, hands) at the bottom; spec (the object, its contacts,
# the motion, the problems) on them; transcription (collocation, parameters, the grasp
# model, the NLP from blocks); certify (the certificate's laws; its types,
# certify.certificate, are a leaf that every layer may use and that imports nothing of the
# core); the solution; solve (IPOPT, guesses and strategies, the pipeline); the front ends
# (ball_on_palm, one_finger) on the pipeline; methods (greedy) on everything. Each layer
# imports only the layers listed for it (and itself).

CORE_LAYERS: dict[str, set[str]] = {
    "geometry": set(),
    "robots": {"geometry"},
    "spec": {"geometry", "robots", "certify.certificate"},
    "transcription": {"geometry", "robots", "spec", "certify.certificate"},
    "certify": {"geometry", "robots", "spec", "transcription"},
    "solution": {"geometry", "spec", "transcription", "certify.certificate"},
    "solve": {"geometry", "robots", "spec", "transcription", "certify", "solution"},
    "ball_on_palm": {"geometry", "spec", "transcription", "certify", "solution", "solve"},
    "one_finger": {"geometry", "robots", "spec", "transcription", "solution", "solve"},
    "methods": {"geometry", "robots", "spec", "transcription", "certify", "solution", "solve",
                "ball_on_palm", "one_finger"},
}


def _layer(module: str) -> str:
    """The layer of an ``ocp`` module: its subpackage, or the top-level module's name;
    ``certify.certificate`` (the certificate's types) is a layer of its own."""
    parts = module.split(".")[1:]
    if parts[:2] == ["certify", "certificate"]:
        return "certify.certificate"
    return parts[0] if parts else ""


def test_the_core_imports_only_down_its_layers() -> None:
    offenders = []
    for path in OCP.rglob("*.py"):
        module = ".".join(path.relative_to(OCP.parent).with_suffix("").parts)
        layer = _layer(module.removesuffix(".__init__"))
        if layer in ("", "__init__"):
            continue  # the package's public API re-exports every layer
        # the certificate's types: a leaf that every layer may use
        allowed = CORE_LAYERS.get(layer, set()) | {layer}
        if layer != "certify.certificate":
            allowed |= {"certify.certificate"}
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                assert node.level == 0, f"{module}: relative import of {node.module}"
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                if name.split(".")[0] == "ocp" and name != "ocp" and \
                        _layer(name) not in allowed:
                    offenders.append(f"{module} ({layer}) imports {name}")
    assert not offenders, "\n".join(offenders)


def test_every_core_module_is_in_a_layer() -> None:
    layers = {_layer(".".join(p.relative_to(OCP.parent).with_suffix("").parts))
              for p in OCP.rglob("*.py") if p.name != "__init__.py" or p.parent != OCP}
    assert layers - {"", "__init__"} <= set(CORE_LAYERS) | {"certify.certificate"}, layers
