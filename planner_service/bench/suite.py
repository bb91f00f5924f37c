"""Benchmark suites as data: families of random problems drawn from a seed, and fixed
members, each a wire request (see docs/benchmarks.md for the format).

:func:`load_suite` reads a suite (a name of one shipped in ``suites/``, or a path);
:func:`expand` turns it into :class:`Problem` s (deterministic: the same suite gives the same
requests); :func:`units` pairs each problem with the methods that apply to it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .generators import GENERATORS, GeneratorError

__all__ = [
    "EXPECTATIONS",
    "METHODS",
    "PEER_METHODS",
    "Problem",
    "Suite",
    "SuiteError",
    "Unit",
    "applicable",
    "builtin_suites",
    "expand",
    "load_suite",
    "units",
]

#: Every method a suite may name, in report order: the planners' own (``collocation`` for
#: every request, ``greedy`` for one-finger requests) and the peers' (ball-on-palm only).
METHODS: tuple[str, ...] = ("collocation", "greedy", "drake", "casadi_plain")
#: The methods provided by ``planner_service.bench.peers`` (when installed).
PEER_METHODS: tuple[str, ...] = ("drake", "casadi_plain")
#: What a suite may expect of a (problem, method): ``solved`` (solved with a passed
#: certificate, else the run exits 1), ``unsolved`` (a known failure, kept in the suite as
#: a finding) or ``any`` (recorded, never judged).
EXPECTATIONS: tuple[str, ...] = ("solved", "unsolved", "any")


class SuiteError(ValueError):
    """A suite file that cannot be read or expanded."""


def applicable(planner: str, method: str) -> bool:
    """Whether ``method`` can plan a request of ``planner``."""
    if method == "collocation":
        return True
    if method == "greedy":
        return planner == "one_finger"
    return method in PEER_METHODS and planner == "ball_on_palm"


@dataclass(frozen=True)
class Problem:
    """One planning problem of a suite: a wire request (JSON dict) and what is expected of
    each method on it."""

    family: str
    id: str
    request: dict[str, Any]
    expected: dict[str, str]  # method -> one of EXPECTATIONS
    methods: tuple[str, ...]  # the methods the suite runs on it (before applicability)
    notes: tuple[str, ...] = ()
    comments: dict[str, str] = field(default_factory=dict)  # method -> why so expected

    @property
    def planner(self) -> str:
        return str(self.request.get("planner", "ball_on_palm"))


@dataclass(frozen=True)
class Unit:
    """One run: a problem with one method (the request it runs is the problem's, with
    ``"method": "greedy"`` for the greedy method)."""

    family: str
    problem_id: str
    method: str
    planner: str
    request: dict[str, Any]
    expected: str

    @property
    def key(self) -> tuple[str, str, str]:
        return (self.family, self.problem_id, self.method)


@dataclass(frozen=True)
class Suite:
    name: str
    source: str
    data: dict[str, Any]

    @property
    def description(self) -> str:
        return str(self.data.get("description", ""))

    @property
    def family_names(self) -> list[str]:
        names = [str(f["name"]) for f in self.data.get("families", [])]
        for member in self.data.get("fixed", []):
            if member["family"] not in names:
                names.append(str(member["family"]))
        return names


def builtin_suites() -> list[str]:
    """Names of the suites shipped with the package."""
    folder = resources.files("planner_service.bench") / "suites"
    return sorted(p.name.removesuffix(".json") for p in folder.iterdir()
                  if p.name.endswith(".json"))


def load_suite(name_or_path: str | Path) -> Suite:
    """A shipped suite by name (``quick``, ``full``) or a suite JSON file."""
    text = str(name_or_path)
    if text in builtin_suites():
        source = resources.files("planner_service.bench") / "suites" / f"{text}.json"
        raw = source.read_text(encoding="utf-8")
        where = f"planner_service/bench/suites/{text}.json"
    else:
        path = Path(text)
        if not path.is_file():
            raise SuiteError(f"no suite {text!r}: neither a shipped suite "
                             f"({', '.join(builtin_suites())}) nor a file")
        raw, where = path.read_text(encoding="utf-8"), str(path)
    try:
        data = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise SuiteError(f"{where} is not valid JSON: {exc}") from exc
    _check(data, where)
    return Suite(str(data.get("name", Path(where).stem)), where, data)


def _check(data: Any, where: str) -> None:
    if not isinstance(data, dict):
        raise SuiteError(f"{where}: a suite is a JSON object")
    problems = []
    for key in ("families", "fixed"):
        if not isinstance(data.get(key, []), list):
            problems.append(f"`{key}` must be a list")
    for i, f in enumerate(data.get("families", [])):
        missing = [k for k in ("name", "generator", "count", "seed") if k not in f]
        if missing:
            problems.append(f"families[{i}] lacks {missing}")
        elif f["generator"] not in GENERATORS:
            problems.append(f"families[{i}].generator {f['generator']!r} is not one of "
                            f"{sorted(GENERATORS)}")
    for i, m in enumerate(data.get("fixed", [])):
        missing = [k for k in ("family", "id", "request") if k not in m]
        if missing:
            problems.append(f"fixed[{i}] lacks {missing}")
    for what, methods in _method_lists(data):
        unknown = sorted(set(methods) - set(METHODS))
        if unknown:
            problems.append(f"{what}: unknown methods {unknown}; known: {list(METHODS)}")
    if problems:
        raise SuiteError(f"{where}: " + "; ".join(problems))


def _method_lists(data: dict[str, Any]) -> list[tuple[str, list[str]]]:
    out = [("methods", list(data.get("methods", METHODS)))]
    out += [(f"families[{i}].methods", list(f["methods"]))
            for i, f in enumerate(data.get("families", [])) if "methods" in f]
    out += [(f"fixed[{i}].methods", list(m["methods"]))
            for i, m in enumerate(data.get("fixed", [])) if "methods" in m]
    return out


def _expectations(suite_level: Any, own: Any, methods: tuple[str, ...],
                  exceptions: dict[tuple[str, str], dict[str, Any]], problem_id: str
                  ) -> tuple[dict[str, str], dict[str, str]]:
    """method -> expectation (the exception for this problem and method, else the
    member's or family's ``expected``, else the suite's, else ``solved``) and method ->
    the note of an exception."""
    def level(value: Any, method: str) -> str | None:
        if isinstance(value, str):
            return value
        if isinstance(value, dict):
            got = value.get(method)
            return None if got is None else str(got)
        return None

    expected, notes = {}, {}
    for m in methods:
        exc = exceptions.get((problem_id, m))
        value = (str(exc["expected"]) if exc is not None else None) or level(own, m) \
            or level(suite_level, m) or "solved"
        if value not in EXPECTATIONS:
            raise SuiteError(f"{problem_id}: expected {value!r} for {m}; one of "
                             f"{list(EXPECTATIONS)}")
        expected[m] = value
        if exc is not None and exc.get("note"):
            notes[m] = str(exc["note"])
    return expected, notes


def expand(suite: Suite, families: list[str] | None = None, limit: int | None = None
           ) -> list[Problem]:
    """The suite's problems, in suite order: each family's ``count`` draws from
    ``numpy.random.default_rng(seed)`` (all drawn, then the first ``limit`` kept, so that a
    limited run is a prefix of the full one), then the fixed members. ``families``: keep
    only these family names (unknown names raise SuiteError)."""
    data = suite.data
    if families is not None:
        unknown = sorted(set(families) - set(suite.family_names))
        if unknown:
            raise SuiteError(f"unknown families {unknown}; the suite has "
                             f"{suite.family_names}")
    wanted = set(families) if families is not None else None
    suite_methods = tuple(data.get("methods", METHODS))
    exceptions = {(str(e["id"]), str(e["method"])): e for e in data.get("exceptions", [])}
    out: list[Problem] = []
    for fam in data.get("families", []):
        name = str(fam["name"])
        if wanted is not None and name not in wanted:
            continue
        rng = np.random.default_rng(int(fam["seed"]))
        methods = tuple(fam.get("methods", suite_methods))
        generate = GENERATORS[fam["generator"]]
        for i in range(int(fam["count"])):
            try:
                request, notes = generate(rng, dict(fam.get("params", {})))
            except GeneratorError as exc:
                raise SuiteError(f"family {name}: {exc}") from exc
            pid = f"{name}-{i:03d}"
            expected, comments = _expectations(data.get("expected"), fam.get("expected"),
                                               methods, exceptions, pid)
            if limit is None or i < limit:
                out.append(Problem(name, pid, request, expected, methods, tuple(notes),
                                   comments))
    counts: dict[str, int] = {}
    for member in data.get("fixed", []):
        name = str(member["family"])
        if wanted is not None and name not in wanted:
            continue
        counts[name] = counts.get(name, 0) + 1
        if limit is not None and counts[name] > limit:
            continue
        methods = tuple(member.get("methods", suite_methods))
        pid = str(member["id"])
        expected, comments = _expectations(data.get("expected"), member.get("expected"),
                                           methods, exceptions, pid)
        out.append(Problem(name, pid, dict(member["request"]), expected, methods,
                           tuple(member.get("notes", ())), comments))
    ids = [p.id for p in out]
    if len(set(ids)) != len(ids):
        raise SuiteError("problem ids must be unique: " + ", ".join(
            sorted({i for i in ids if ids.count(i) > 1})))
    return out


def units(problems: list[Problem], methods: list[str] | None = None) -> list[Unit]:
    """Every (problem, method) to run: the problem's methods that apply to its planner
    (and are in ``methods``, when given), sorted by (family, problem id, method)."""
    out = []
    for p in problems:
        for m in p.methods:
            if (methods is not None and m not in methods) or not applicable(p.planner, m):
                continue
            request = dict(p.request, method="greedy") if m == "greedy" else p.request
            out.append(Unit(p.family, p.id, m, p.planner, request, p.expected[m]))
    return sorted(out, key=lambda u: u.key)
