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


def test_the_wires_object_shapes_are_the_core_registry() -> None:
    """``object.shape``'s names on the wire are :data:`ocp.shapes.SHAPES`'s, and its
    dimensions allow each shape's longest form."""
    import typing

    from dexroll_client.requests import ObjectModel
    from ocp.shapes import SHAPES

    field = ObjectModel.model_fields["shape"]
    assert set(typing.get_args(field.annotation)) == set(SHAPES)
    longest = max(len(s.parameters) for s in SHAPES.values())
    lengths = [m.max_length for m in ObjectModel.model_fields["dimensions"].metadata
               if hasattr(m, "max_length")]
    assert lengths == [longest]


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


def _core_names(folder: str) -> list[str]:
    """The core modules a service folder's files import, as ``file: module``."""
    return [f"{p.relative_to(SERVICE)}: {m}" for p in (SERVICE / folder).rglob("*.py")
            for m in sorted(_imports(p)) if m == "ocp" or m.startswith("ocp.")]


def test_the_bench_peers_use_the_public_core() -> None:
    """The benchmarks' peers re-use the ball-on-palm NLP's pieces through the names ``ocp``
    exports, never the solver's internals."""
    used = _imports(SERVICE / "bench" / "peers.py")
    assert "ocp" in used and not [m for m in used if m.startswith("ocp.")]


def _ocp_all() -> set[str]:
    import ocp

    return set(ocp.__all__)


def test_the_viewer_and_the_execution_use_the_public_core_only() -> None:
    """The viewer and the execution read results; the core's models they draw and run
    with come from ``ocp``'s public names (or the planners' adapters), never its
    internals."""
    public = {"ocp"} | {f"ocp.{n}" for n in _ocp_all()}
    offenders = [line for folder in ("view", "execution", "plans") for line in _core_names(folder)
                 if line.split(": ")[1] not in public]
    assert not offenders, offenders


def test_the_service_folders_keep_their_places() -> None:
    """bench, view and execution sit beside the jobs: neither the API nor the jobs, the
    viewer never the bench or the execution, the execution never the viewer; the readers
    of a finished plan both use (plans) none of them."""
    up = ("planner_service.api", "planner_service.jobs", "fastapi", "starlette")
    assert not _offenders("bench", up)
    assert not _offenders("view", (*up, "planner_service.bench",
                                   "planner_service.execution"))
    assert not _offenders("execution", (*up, "planner_service.bench"))
    # the plan's readers they share sit beside both, below them
    assert not _offenders("execution", ("planner_service.view",))
    assert not _offenders("plans", (*up, "planner_service.bench", "planner_service.view",
                                    "planner_service.execution"))


# -- the core's own layers -------------------------------------------------------------------
#
# The data flow in the folder names: certify (the certificate's types: a leaf that imports
# nothing of the core and that every layer may use); geometry (surfaces, contact
# kinematics, rotations, grasp geometry), shapes (the objects' shapes, on geometry) and
# robots (fingers, hands) at the bottom; spec
# (the problems: data) on them; contacts (each contact kind's CasADi model) on spec;
# transcription (collocation, parameters, the grasp model, the NLP from blocks); the
# solution; solve (IPOPT, guesses and strategies, the pipeline, the certification of a
# plan); the front ends (ball_on_palm, one_finger) on the pipeline; methods (greedy) on
# everything; gait (finger gaiting) on the pipeline; control (tracking a plan at a
# controller's rate) on the pipeline. Each layer imports only the layers
# listed for it (and itself, and certify).

CORE_LAYERS: dict[str, set[str]] = {
    "certify": set(),
    "geometry": set(),
    "shapes": {"geometry"},
    "robots": {"geometry", "shapes"},
    "spec": {"geometry", "shapes", "robots"},
    "contacts": {"geometry", "shapes", "robots", "spec"},
    "transcription": {"geometry", "shapes", "robots", "spec", "contacts"},
    "solution": {"geometry", "shapes", "spec", "transcription"},
    "solve": {"geometry", "shapes", "robots", "spec", "contacts", "transcription", "solution"},
    "ball_on_palm": {"geometry", "shapes", "spec", "contacts", "transcription", "solution",
                     "solve"},
    "one_finger": {"geometry", "shapes", "robots", "spec", "transcription", "solution",
                   "solve"},
    "presets": {"robots", "shapes", "spec", "ball_on_palm", "one_finger"},
    "methods": {"geometry", "shapes", "robots", "spec", "contacts", "transcription",
                "solution", "solve", "ball_on_palm", "one_finger"},
    "gait": {"geometry", "shapes", "robots", "spec", "contacts", "transcription", "solution",
             "solve"},
    "control": {"shapes", "spec", "transcription", "solution", "solve"},
}


def _layer(module: str) -> str:
    """The layer of an ``ocp`` module: its subpackage, or the top-level module's name."""
    parts = module.split(".")[1:]
    return parts[0] if parts else ""


def _core_imports(path: Path) -> list[str]:
    """The ``ocp`` modules a core source file imports (the core has no relative imports)."""
    module = ".".join(path.relative_to(OCP.parent).with_suffix("").parts)
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            assert node.level == 0, f"{module}: relative import of {node.module}"
            names.append(node.module)
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names]
    return [n for n in names if n.split(".")[0] == "ocp" and n != "ocp"]


def test_the_core_imports_only_down_its_layers() -> None:
    offenders = []
    for path in OCP.rglob("*.py"):
        module = ".".join(path.relative_to(OCP.parent).with_suffix("").parts)
        layer = _layer(module.removesuffix(".__init__"))
        if layer in ("", "__init__"):
            continue  # the package's public API re-exports every layer
        allowed = CORE_LAYERS.get(layer, set()) | {layer}
        if layer != "certify":  # the certificate's types: a leaf every layer may use
            allowed |= {"certify"}
        offenders += [f"{module} ({layer}) imports {name}" for name in _core_imports(path)
                      if _layer(name) not in allowed]
    assert not offenders, "\n".join(offenders)


def test_the_layers_are_ordered() -> None:
    """No two layers may import each other: the allowed imports form an order."""
    def below(layer: str, seen: frozenset[str] = frozenset()) -> set[str]:
        assert layer not in seen, f"a cycle through {layer}"
        out = set(CORE_LAYERS[layer])
        for lower in CORE_LAYERS[layer]:
            out |= below(lower, seen | {layer})
        return out

    for layer in CORE_LAYERS:
        assert layer not in below(layer)


def test_every_core_module_is_in_a_layer() -> None:
    layers = {_layer(".".join(p.relative_to(OCP.parent).with_suffix("").parts))
              for p in OCP.rglob("*.py") if p.name != "__init__.py" or p.parent != OCP}
    assert layers - {"", "__init__"} <= set(CORE_LAYERS), layers


def test_the_problem_descriptions_are_data() -> None:
    """``ocp.spec`` describes problems: no CasADi, no Pinocchio (the models are the
    contacts' and the robots'), nothing of the certificate but its tolerance policies."""
    offenders = []
    for path in (OCP / "spec").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [(a.name, a.name) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [(node.module, a.name) for a in node.names]
            else:
                continue
            for module, name in names:
                if module.split(".")[0] in ("casadi", "pinocchio") or (
                        module.startswith("ocp.certify") and "TOLERANCES" not in name
                        and name != "TolerancePolicy"):
                    offenders.append(f"{path.name}: {module}.{name}")
    assert not offenders


def test_the_certificate_types_are_a_leaf() -> None:
    """``ocp.certify`` holds the certificate's types alone: the certification of a plan
    (which reads the transcription) is the solve layer's."""
    assert sorted(p.name for p in (OCP / "certify").glob("*.py")) == ["__init__.py",
                                                                      "certificate.py"]
    for path in (OCP / "certify").glob("*.py"):
        assert not _core_imports(path), path.name
