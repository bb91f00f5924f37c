"""Compiled NLP solvers: CasADi code generation, gcc, and an on-disk cache by structure.

An IPOPT solver built from CasADi expressions evaluates its functions (constraints, their
Jacobian, the Hessian of the Lagrangian) in CasADi's virtual machine. For a structure that
is solved many times the same functions can be generated as C, compiled once into a shared
library and loaded with ``nlpsol(name, "ipopt", library)``: on the ball-on-palm triangle at
N = 50 IPOPT's time drops by about a third (docs/performance.md). The compile is slow
(tens of seconds for N = 50 at ``-O1``), so it is an option, and the library is kept in
``cache_dir`` under a name made from the structure's key, the generated code's hash, the
CasADi version and the compiler flags: the next process that needs the structure loads it.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Any

import casadi as ca

__all__ = ["compiled_solver"]

_CWD_LOCK = threading.Lock()
DEFAULT_FLAGS = ("-O1",)


def _generate(solver: ca.Function, name: str, folder: Path) -> Path:
    """The solver's problem functions as C (``generate_dependencies``: the problem "nlp" and
    every derivative function IPOPT asks for). CasADi writes that file into the working
    directory only, so the directory is changed for the call, under a lock."""
    with _CWD_LOCK:
        cwd = Path.cwd()
        os.chdir(folder)
        try:
            solver.generate_dependencies(f"{name}.c", {"with_header": False})
        finally:
            os.chdir(cwd)
    return folder / f"{name}.c"


def compiled_solver(solver: ca.Function, key: str, options: dict[str, Any],
                    cache_dir: Path, flags: tuple[str, ...] = DEFAULT_FLAGS,
                    compiler: str = "gcc") -> tuple[ca.Function, bool]:
    """An IPOPT solver with ``solver``'s problem, its functions compiled to a shared library
    cached in ``cache_dir``; ``options`` are nlpsol's (the same as ``solver``'s). Returns
    (the solver, whether the library came from the cache). Raises RuntimeError when the
    compiler is missing or fails (the caller keeps ``solver``)."""
    if shutil.which(compiler) is None:
        raise RuntimeError(f"no C compiler {compiler!r} on PATH")
    cache_dir.mkdir(parents=True, exist_ok=True)
    name = "dexroll_nlp"
    with tempfile.TemporaryDirectory(dir=cache_dir) as tmp:
        source = _generate(solver, name, Path(tmp))
        digest = hashlib.sha256()
        for part in (key, ca.__version__, compiler, *flags):
            digest.update(part.encode())
        digest.update(source.read_bytes())
        library = cache_dir / f"{digest.hexdigest()[:24]}.so"
        hit = library.exists()
        if not hit:
            out = Path(tmp) / "lib.so"
            proc = subprocess.run([compiler, *flags, "-fPIC", "-shared", str(source), "-o",
                                   str(out)], capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                raise RuntimeError(f"{compiler} failed: {proc.stderr[-2000:]}")
            os.replace(out, library)  # atomic: concurrent processes never see a partial file
    return ca.nlpsol(f"{solver.name()}_compiled", "ipopt", str(library), options), hit
