"""Compiled NLP solvers: CasADi code generation, gcc, and an on-disk cache by structure.

An IPOPT solver built from CasADi expressions evaluates its functions (constraints, their
Jacobian, the Hessian of the Lagrangian) in CasADi's virtual machine. For a structure that
is solved many times the same functions can be generated as C, compiled once into a shared
library and loaded with ``nlpsol(name, "ipopt", library)``: for the block NLPs of
:mod:`ocp.transcription.nlp_blocks` (every grasp, the object on the palm alone included)
the problem's
functions and the block derivatives each make a library (IPOPT ~40 % faster on experiment
1, docs/performance.md). The compile takes seconds, so it is an option, and the libraries
are kept in ``cache_dir`` under names made from the structure's key, the generated code's
hash, the CasADi version and the compiler flags: the next process that needs the
structure loads them.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import casadi as ca

__all__ = [
    "BackgroundCompiler",
    "block_libraries",
    "block_sources",
    "compile_sources",
    "compiled_block_solver",
    "compiled_functions",
    "load_block_solver",
]

_CWD_LOCK = threading.Lock()


@contextmanager
def _working_directory(folder: Path) -> Iterator[None]:
    """CasADi writes generated C into the working directory only: change it for the call,
    under a lock (other threads of the process see the change)."""
    with _CWD_LOCK:
        cwd = Path.cwd()
        os.chdir(folder)
        try:
            yield
        finally:
            os.chdir(cwd)


def _generate(solver: ca.Function, name: str, folder: Path) -> Path:
    """The solver's problem functions as C (``generate_dependencies``: the problem "nlp" and
    every derivative function IPOPT asks for), written into ``folder``."""
    with _working_directory(folder):
        solver.generate_dependencies(f"{name}.c", {"with_header": False})
    return folder / f"{name}.c"


def _generate_functions(functions: list[ca.Function], name: str, folder: Path) -> Path:
    """C for the given functions (one file), written into ``folder``."""
    cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for fn in functions:
        cg.add(fn)
    with _working_directory(folder):
        cg.generate()
    return folder / f"{name}.c"


def _check_compiler(compiler: str, cache_dir: Path) -> None:
    if shutil.which(compiler) is None:
        raise RuntimeError(f"no C compiler {compiler!r} on PATH")
    cache_dir.mkdir(parents=True, exist_ok=True)


def _cached_library(source: Path, key: str, cache_dir: Path, flags: tuple[str, ...],
                    compiler: str) -> tuple[Path, bool]:
    """The shared library of ``source`` in ``cache_dir``, named by the hash of the key, the
    CasADi version, the compiler and flags, and the C itself: compiled next to the source
    (a temporary folder) and moved into place unless it is already there. Returns (the
    library, whether it came from the cache).

    Processes sharing ``cache_dir`` (a service's workers, warming up the same structures at
    once) take turns on each library with a lock (``flock`` on ``.locks/<name>.lock``,
    released by the system if a process dies): the second finds the first's library
    instead of compiling it again."""
    digest = hashlib.sha256()
    for part in (key, ca.__version__, compiler, *flags):
        digest.update(part.encode())
    digest.update(source.read_bytes())
    name = digest.hexdigest()[:24]
    library = cache_dir / f"{name}.so"
    if library.exists():
        return library, True
    locks = cache_dir / ".locks"
    locks.mkdir(exist_ok=True)
    with open(locks / f"{name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if library.exists():
                return library, True
            out = source.with_suffix(".so")
            proc = subprocess.run([compiler, *flags, "-fPIC", "-shared", str(source), "-o",
                                   str(out)], capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                raise RuntimeError(f"{compiler} failed: {proc.stderr[-2000:]}")
            os.replace(out, library)  # atomic: other processes never see a partial file
            return library, False
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def block_libraries(oracle: ca.Function, options: dict[str, Any], key: str,
                    cache_dir: Path, flags: tuple[str, ...] = ("-O2",),
                    compiler: str = "gcc") -> tuple[list[Path], list[bool]]:
    """The cached shared libraries of a block NLP (:func:`block_sources`), each compiled
    unless the cache has it, and whether the cache had each. RuntimeError when the compiler
    is missing or fails."""
    _check_compiler(compiler, cache_dir)
    with tempfile.TemporaryDirectory(dir=cache_dir) as tmp:
        sources = block_sources(oracle, options, Path(tmp))
        out = [_cached_library(source, key, cache_dir, flags, compiler) for source in sources]
    return [lib for lib, _ in out], [hit for _, hit in out]


def block_sources(oracle: ca.Function, options: dict[str, Any], folder: Path
                  ) -> list[Path]:
    """The C of a block NLP (see :func:`compiled_block_solver`), written into ``folder``:
    the problem's own functions (objective, constraints, gradient), then the two derivative
    functions ``options["jac_g"]`` and ``options["hess_lag"]``. CasADi calls: the caller's
    thread."""
    # the problem as expressions: the generated functions are then named nlp_f, nlp_g, ...
    # as nlpsol looks them up in a library
    x = ca.MX.sym("x", oracle.size1_in(0))
    p = ca.MX.sym("p", oracle.size1_in(1))
    f, g = oracle(x, p)
    solver = ca.nlpsol("manipulation_plain", "ipopt", {"x": x, "p": p, "f": f, "g": g},
                       options)
    return [_generate(solver, "dexroll_nlp", folder),
            _generate_functions([options["jac_g"], options["hess_lag"]],
                                "dexroll_derivatives", folder)]


def compiled_functions(functions: list[ca.Function], key: str, cache_dir: Path,
                       flags: tuple[str, ...] = ("-O2",), compiler: str = "gcc"
                       ) -> list[ca.Function]:
    """The given CasADi functions generated as C into one shared library (cached in
    ``cache_dir`` under the hash of its C, as every library here) and loaded back, in
    order. RuntimeError when the compiler is missing or fails."""
    _check_compiler(compiler, cache_dir)
    with tempfile.TemporaryDirectory(dir=cache_dir) as tmp:
        source = _generate_functions(functions, "dexroll_functions", Path(tmp))
        library, _ = _cached_library(source, key, cache_dir, flags, compiler)
    return [ca.external(fn.name(), str(library)) for fn in functions]


def compile_sources(sources: list[Path], key: str, cache_dir: Path,
                    flags: tuple[str, ...] = ("-O2",), compiler: str = "gcc") -> list[Path]:
    """The cached shared library of each source (compiled unless the cache has it). No
    CasADi call: safe in a background thread."""
    return [_cached_library(source, key, cache_dir, flags, compiler)[0] for source in sources]


def load_block_solver(libraries: list[Path], options: dict[str, Any]
                      ) -> tuple[ca.Function, dict[str, Any]]:
    """The IPOPT solver of :func:`block_sources`' libraries, and its options with the
    compiled derivative functions. CasADi calls: the caller's thread."""
    compiled = {**options, **{k: ca.external(options[k].name(), str(libraries[1]))
                              for k in ("jac_g", "hess_lag")}}
    return ca.nlpsol("manipulation_compiled", "ipopt", str(libraries[0]), compiled), compiled


def compiled_block_solver(oracle: ca.Function, options: dict[str, Any], key: str,
                          cache_dir: Path, flags: tuple[str, ...] = ("-O2",),
                          compiler: str = "gcc") -> tuple[ca.Function, dict[str, Any]]:
    """An IPOPT solver of the problem ``oracle`` ((x, p) -> (f, g)) whose derivatives are
    the functions ``options["jac_g"]`` and ``options["hess_lag"]`` (the block-assembled ones
    of :mod:`ocp.transcription.nlp_blocks`), everything compiled: the problem's own functions
    (objective,
    constraints, gradient) and the two derivative functions, each a shared library cached in
    ``cache_dir`` under the hash of its C. Returns (the solver, its options with the
    compiled derivative functions). RuntimeError when the compiler is missing or fails."""
    libraries, _ = block_libraries(oracle, options, key, cache_dir, flags, compiler)
    return load_block_solver(libraries, options)


class BackgroundCompiler:
    """Compiles block NLPs while their owner keeps solving with the virtual machine.

    :meth:`submit` writes an NLP's C (CasADi, in the caller's thread: ~0.1-0.2 s) and hands
    the gcc runs (seconds) to a background thread; :meth:`finished` returns, in the
    caller's thread, the compiled solvers of the compiles that are done, loaded, for the
    owner to swap in between solves. CasADi is only ever called from the caller's thread.
    A compile that fails (no compiler, gcc error) is dropped and reported once in
    :attr:`errors`: the owner goes on with the virtual machine.
    """

    def __init__(self, cache_dir: Path, flags: tuple[str, ...] = ("-O2",),
                 compiler: str = "gcc") -> None:
        self.cache_dir, self.flags, self.compiler = cache_dir, flags, compiler
        self._executor: ThreadPoolExecutor | None = None
        self._pending: dict[Any, tuple[Future[list[Path]], dict[str, Any]]] = {}
        self.errors: list[str] = []

    def submit(self, key: Any, oracle: ca.Function, options: dict[str, Any],
               fingerprint: str) -> bool:
        """Start compiling the NLP ``(oracle, options)`` known to the owner as ``key``;
        False (and a reason in :attr:`errors`) when there is no compiler."""
        try:
            _check_compiler(self.compiler, self.cache_dir)
        except RuntimeError as exc:
            self.errors.append(str(exc))
            return False
        tmp = tempfile.mkdtemp(prefix="build-", dir=self.cache_dir)
        sources = block_sources(oracle, options, Path(tmp))
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1,
                                                thread_name_prefix="dexroll-compile")
        future = self._executor.submit(self._compile, sources, fingerprint, tmp)
        self._pending[key] = (future, options)
        return True

    def _compile(self, sources: list[Path], fingerprint: str, tmp: str) -> list[Path]:
        try:
            return compile_sources(sources, fingerprint, self.cache_dir, self.flags,
                                   self.compiler)
        finally:  # the C is not needed once compiled (or failed)
            shutil.rmtree(tmp, ignore_errors=True)

    @property
    def pending(self) -> int:
        return len(self._pending)

    def finished(self, wait: float = 0.0) -> list[tuple[Any, ca.Function, dict[str, Any]]]:
        """(key, compiled solver, its options) of every compile done (waiting up to ``wait``
        seconds for the pending ones), loaded in the caller's thread."""
        if wait > 0 and self._pending:
            futures_wait([f for f, _ in self._pending.values()], timeout=wait)
        out = []
        for key, (future, options) in list(self._pending.items()):
            if not future.done():
                continue
            del self._pending[key]
            try:
                solver, compiled = load_block_solver(future.result(), options)
                out.append((key, solver, compiled))
            except (RuntimeError, OSError) as exc:
                self.errors.append(str(exc))
        return out
