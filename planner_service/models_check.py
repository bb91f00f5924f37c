"""Model files from requests (a finger's URDF, a whole hand's URDF or MJCF) checked in an
isolated process before the service loads them.

A request may carry a robot model as XML text. Loading it costs what its author wants it to
cost: Pinocchio and the finger's CasADi kinematics grow like the cube of the joint count (a
77 KB chain of 400 joints took 8-11 s in the API process). So the API never loads a model
it has not seen checked by a :class:`ModelChecker`: a pool of spawned processes, each under
a memory limit (``RLIMIT_AS``), each check under a time limit (the process is killed and
replaced past it), that

1. checks the text's size (:attr:`ModelLimits.max_bytes`),
2. parses it as XML without entities or a DOCTYPE, element by element, stopping as soon as
   the tree exceeds a limit (elements, nesting depth),
3. counts the kinematic tree on the parsed XML (joints, links/bodies, chain depth) against
   :class:`ModelLimits` -- all before Pinocchio sees the text --
4. and only then loads the model with the loader of its kind (:data:`LOADERS`; for a URDF
   the service's own :func:`~ocp.robots.finger.load_finger`), which checks the rest (a tip
   frame that exists, a serial chain, the joint count the planners support).

Every reason comes back as ``(field, reason)`` under the model's own field (``urdf``,
``tip_frame``), for the caller to prefix with where the model is in the request
(:func:`request_models`). Generic over model kinds: a kind is a tree counter
(:data:`COUNTERS`) and a loader (:data:`LOADERS`); MJCF registers both.

Other work that loads a request's models runs in such processes too, under the same
limits (:meth:`ModelChecker.call` of a :class:`Task`): the rest of a request's checks once
its models passed (its fingers loaded, the inverse kinematics of its grasp), and the
viewer's page of a plan (its fingers' geometry loaded from their URDFs). The API process
never loads a model a request carries.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import json
import logging
import queue
import re
import threading
import time
import xml.etree.ElementTree as ET
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from typing import Any, cast

from pydantic import BaseModel

from .executors import Executor, Resources, Worker, WorkerError, WorkerLostError

__all__ = [
    "COUNTERS",
    "LOADERS",
    "TASKS",
    "CheckerBusyError",
    "ModelChecker",
    "ModelLimits",
    "ModelText",
    "Task",
    "TaskError",
    "TaskLimitError",
    "TreeSize",
    "check_model",
    "file_references",
    "parse_tree",
    "request_errors_of",
    "request_models",
    "without_file_references",
]

log = logging.getLogger("dexroll.models")

FieldErrors = list[tuple[str, str]]


@dataclass(frozen=True)
class ModelLimits:
    """What a model from a request may be (DEXROLL_MODEL_* settings)."""

    #: characters of the text
    max_bytes: int = 500_000
    #: XML elements, and their nesting depth
    max_elements: int = 20_000
    max_xml_depth: int = 64
    #: joints (every kind: fixed ones too), links (MJCF: bodies), and the longest chain
    #: of joints from the root
    max_joints: int = 64
    max_links: int = 128
    max_chain_depth: int = 32
    #: one check's wall time [s] and the checker process's memory beyond its own [bytes]
    time_limit: float = 5.0
    memory_bytes: int = 512 << 20


@dataclass(frozen=True)
class TreeSize:
    """A model's kinematic tree, counted on the parsed XML."""

    joints: int
    links: int
    chain_depth: int


@dataclass(frozen=True)
class ModelText:
    """A model carried by a request: where (``finger``, ``fingers[1].finger``), its kind
    (``urdf``), the field holding the text, the text, and what its loader needs."""

    where: str
    kind: str
    field: str
    text: str
    params: tuple[tuple[str, Any], ...] = ()

    def key(self) -> str:
        digest = hashlib.sha256(self.text.encode("utf-8", "surrogatepass"))
        digest.update(repr((self.kind, self.params)).encode())
        return digest.hexdigest()


#: A DOCTYPE or entity declaration, anywhere in a model's text (any case).
_DECLARATION = re.compile(r"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
#: Attributes by which a model names a file its loader would open (URDF: a <mesh>'s or a
#: <texture>'s ``filename``; MJCF: ``file`` of <include>, <mesh>, <texture>, <hfield>, and
#: the <compiler>'s folders).
_FILE_ATTRIBUTES = ("filename", "file", "meshdir", "texturedir", "assetdir")


def file_references(root: ET.Element) -> list[tuple[str, str]]:
    """The (element, path) of every file a model's XML names."""
    return [(element.tag, element.get(a, "")) for element in root.iter()
            for a in _FILE_ATTRIBUTES if a in element.attrib]


def without_file_references(urdf: str) -> str:
    """A URDF without the elements that name files: each <visual> or <collision> whose
    geometry is a <mesh filename=...>, and any other element with a file attribute (a
    material's <texture>). What Pinocchio's geometry loader gets from the viewer (and the
    execution): the service never opens a path a request names; the meshes were not drawn
    anyway. ValueError when the text declares a DOCTYPE or entities or is not XML."""
    if _DECLARATION.search(urdf):
        raise ValueError("the model declares a DOCTYPE or entities")
    try:
        root = ET.fromstring(urdf)
    except ET.ParseError as exc:
        raise ValueError(f"not a well-formed XML document: {exc}") from exc
    parent = {child: p for p in root.iter() for child in p}
    doomed = []
    for element in root.iter():
        if not any(a in element.attrib for a in _FILE_ATTRIBUTES):
            continue
        node = element
        while node in parent and node.tag not in ("visual", "collision"):
            node = parent[node]
        doomed.append(node if node.tag in ("visual", "collision") else element)
    for element in doomed:
        holder = parent.get(element)
        if holder is not None and any(c is element for c in holder):
            holder.remove(element)
    return ET.tostring(root, encoding="unicode")


class TreeError(ValueError):
    """The XML is not a model this service loads (too large, malformed, not that kind)."""


# -- the parsed tree ---------------------------------------------------------------------------

def parse_tree(text: str, limits: ModelLimits, what: str = "model") -> ET.Element:
    """The XML element tree of ``text``, parsed incrementally: TreeError as soon as it has
    more than ``max_elements`` elements or is nested deeper than ``max_xml_depth``, or when
    it declares a DOCTYPE or entities (never expanded)."""
    if len(text) > limits.max_bytes:
        raise TreeError(f"the model is {len(text)} characters; at most {limits.max_bytes} "
                        "are accepted")
    if _DECLARATION.search(text):  # anywhere: a long comment does not hide one
        raise TreeError("the model declares a DOCTYPE or entities; plain XML only")
    parser: Any = ET.XMLPullParser(events=("start", "end"))
    depth = elements = 0
    root: ET.Element | None = None
    try:
        for start in range(0, len(text), 16_384):
            parser.feed(text[start:start + 16_384])
            for event, item in parser.read_events():
                element = cast(ET.Element, item)
                if event == "start":
                    depth += 1
                    elements += 1
                    if root is None:
                        root = element
                    if depth > limits.max_xml_depth:
                        raise TreeError(f"the model's XML is nested deeper than "
                                        f"{limits.max_xml_depth} elements")
                    if elements > limits.max_elements:
                        raise TreeError(f"the model has more than {limits.max_elements} XML "
                                        "elements")
                else:
                    depth -= 1
        parser.close()
    except ET.ParseError as exc:
        raise TreeError(f"not a well-formed XML document ({what}): {exc}") from exc
    if root is None:
        raise TreeError("no XML element")
    return root


def _urdf_size(root: ET.Element) -> TreeSize:
    if root.tag != "robot":
        raise TreeError(f"a URDF's root element is <robot>, got <{root.tag}>")
    joints = root.findall("joint")
    links = root.findall("link")
    children: dict[str, list[str]] = {}
    has_parent: set[str] = set()
    for j in joints:
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise TreeError(f"joint {j.get('name')!r} needs a <parent> and a <child>")
        p, c = parent.get("link", ""), child.get("link", "")
        if c in has_parent:
            raise TreeError(f"link {c!r} is the child of two joints")
        has_parent.add(c)
        children.setdefault(p, []).append(c)
    roots = {link.get("name", "") for link in links} - has_parent
    if joints and not roots:
        raise TreeError("the joints form a loop: no root link")
    depth, seen = 0, 0
    stack = [(r, 0) for r in roots]
    while stack:  # iterative: a deep chain does not recurse
        name, d = stack.pop()
        seen += 1
        depth = max(depth, d)
        stack.extend((c, d + 1) for c in children.get(name, ()))
    if seen < len(has_parent):
        raise TreeError("the joints form a loop")
    return TreeSize(joints=len(joints), links=len(links), chain_depth=depth)


def _mjcf_size(root: ET.Element) -> TreeSize:
    if root.tag != "mujoco":
        raise TreeError(f"an MJCF model's root element is <mujoco>, got <{root.tag}>")
    named = file_references(root)
    if named:  # Pinocchio's MJCF loader would read them (<include> at least)
        tag, path = named[0]
        raise TreeError(f"the model's <{tag}> names a file ({path!r}): this service reads "
                        "no file a request names; give the model inline, with primitive "
                        "geoms")
    joints = sum(1 for e in root.iter() if e.tag in ("joint", "freejoint"))
    bodies = sum(1 for _ in root.iter("body"))
    depth = 0
    stack = [(b, 1) for b in root.iter("worldbody")]
    while stack:
        element, d = stack.pop()
        for child in element.findall("body"):
            depth = max(depth, d)
            stack.append((child, d + 1))
    return TreeSize(joints=joints, links=bodies, chain_depth=depth)


#: How each kind of model's kinematic tree is counted on its XML.
COUNTERS: dict[str, Callable[[ET.Element], TreeSize]] = {"urdf": _urdf_size,
                                                         "mjcf": _mjcf_size}


def tree_errors(kind: str, text: str, limits: ModelLimits) -> list[str]:
    """What is wrong with a model's text before anything loads it: the reasons, [] if
    none."""
    try:
        size = COUNTERS[kind](parse_tree(text, limits, kind.upper()))
    except TreeError as exc:
        return [str(exc)]
    out = []
    if size.joints > limits.max_joints:
        out.append(f"the model has {size.joints} joints; at most {limits.max_joints} are "
                   "accepted")
    if size.links > limits.max_links:
        out.append(f"the model has {size.links} links; at most {limits.max_links} are "
                   "accepted")
    if size.chain_depth > limits.max_chain_depth:
        out.append(f"the model's kinematic chain is {size.chain_depth} joints deep; at most "
                   f"{limits.max_chain_depth} are accepted")
    return out


# -- loading (in the checker process) ----------------------------------------------------------

def _load_urdf(text: str, params: dict[str, Any]) -> FieldErrors:
    from .planners.cache import hand_model_errors, urdf_errors  # the service's own loaders

    if "tips" in params:  # a whole hand's model (its fingertips named)
        return hand_model_errors(text, "urdf", str(params["tips"]))
    return urdf_errors(text, str(params.get("tip_frame", "fingertip")))


def _load_mjcf(text: str, params: dict[str, Any]) -> FieldErrors:
    from .planners.cache import hand_model_errors  # a whole hand's model

    return hand_model_errors(text, "mjcf", str(params.get("tips", '[{"name": "-"}]')))


#: Each kind's loader, run in the checker process once the tree passed: (text, params) ->
#: errors under the model's fields.
LOADERS: dict[str, Callable[[str, dict[str, Any]], FieldErrors]] = {"urdf": _load_urdf,
                                                                     "mjcf": _load_mjcf}


def check_model(model: ModelText, limits: ModelLimits) -> FieldErrors:
    """Every check of a model, in this process (the checker process runs it): the tree's
    limits, then its kind's loader. Errors under the model's own fields."""
    reasons = tree_errors(model.kind, model.text, limits)
    if reasons:
        return [(model.field, r) for r in reasons]
    return LOADERS[model.kind](model.text, dict(model.params))


#: Work a checker process may be given besides a model's checks, by name: the module and
#: function that do it (imported in the checker process when first asked for).
TASKS: dict[str, tuple[str, str]] = {
    "view": ("planner_service.view", "page_of_job"),
    "request_errors": ("planner_service.models_check", "request_errors_of"),
}


def request_errors_of(request_json: str) -> FieldErrors:
    """Every error of a request (:func:`~planner_service.planners.request_errors`) whose
    models passed their checks, in a checker process: its models loaded there, with this
    process's own fingers, never the API's (whose cache a request without a model uses)."""
    from .planners import REQUEST, request_errors

    return request_errors(REQUEST.validate_json(request_json))


@dataclass(frozen=True)
class Task:
    """One call of a :data:`TASKS` function with ``args`` in a checker process."""

    name: str
    args: tuple[Any, ...]


class TaskError(Exception):
    """The task raised: ``kind`` names its exception's type, ``message`` says why."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind, self.message = kind, message


class TaskLimitError(Exception):
    """The task went past the checker's time or memory limit (its process replaced)."""


def _run_task(task: Task, lim: ModelLimits) -> tuple[str, Any, str]:
    """(status, value, detail) of a task in this process: ("ok", result, ""), ("error",
    exception type name, message) or ("limit", None, reason)."""
    try:
        module, name = TASKS[task.name]
        return "ok", getattr(importlib.import_module(module), name)(*task.args), ""
    except MemoryError:
        return "limit", None, f"it needs more than the {lim.memory_bytes >> 20} MB allowed"
    except Exception as exc:  # the task's own refusal: the caller decides
        return "error", type(exc).__name__, str(exc)


#: A small valid model of each kind, loaded once before a checker reports ready (the
#: MJCF's load imports MuJoCo, whose kinematics checks an MJCF, before the memory limit).
_WARM_UP = {"urdf": '<robot name="warm-up"><link name="fingertip"/></robot>',
            "mjcf": '<mujoco model="warm-up"><worldbody><body name="fingertip"><joint '
                    'name="j" axis="0 0 1" range="-1 1"/><geom size="0.01"/></body>'
                    '</worldbody></mujoco>'}


class CheckWorker:
    """A checker worker's body: the loaders' libraries imported (a small model of each
    kind loaded), then the process's address space capped at its size plus the limits'
    memory (``RLIMIT_AS``) before it checks anything."""

    def __init__(self, limits: dict[str, Any]) -> None:
        import resource

        self.limits = ModelLimits(**limits)
        for kind in LOADERS:  # import the loaders' libraries before the memory limit
            with contextlib.suppress(Exception):
                LOADERS[kind](_WARM_UP.get(kind, ""), {})
        with contextlib.suppress(ValueError, OSError):
            size = 0
            with open("/proc/self/status") as f:
                for line in f:
                    if line.startswith("VmSize:"):
                        size = int(line.split()[1]) * 1024
            if size:
                cap = size + self.limits.memory_bytes
                resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    def ready(self) -> None:
        """The worker is up, under its memory limit."""

    def check(self, model: ModelText) -> FieldErrors:
        """The model's errors (:func:`check_model`), a refusal for one past the limits."""
        try:
            return check_model(model, self.limits)
        except MemoryError:
            return [(model.field, f"loading the model needs more than the "
                                  f"{self.limits.memory_bytes >> 20} MB allowed")]
        except Exception as exc:  # never die on a model
            return [(model.field, f"the model cannot be loaded: {exc!r}")]

    def task(self, task: Task) -> tuple[str, Any, str]:
        """(status, value, detail) of a task (:func:`_run_task`)."""
        return _run_task(task, self.limits)


# -- the checker pool (in the API process) ---------------------------------------------------

class CheckerBusyError(Exception):
    """Every checker process stayed busy for longer than a check may take."""


class ModelChecker:
    """A pool of ``processes`` checker processes (spawned, under ``limits``), and a cache
    of the last verdicts by text. :meth:`check` is thread-safe and blocks the calling
    thread only (it waits on a pipe: the API's event loop and its other threads run)."""

    #: time a new checker process may take to import its libraries [s]
    START_TIMEOUT = 60.0

    def __init__(self, limits: ModelLimits | None = None, processes: int = 1,
                 cache_size: int = 256, lazy: bool = False,
                 executor: Executor | None = None) -> None:
        self.limits = limits or ModelLimits()
        if executor is None:
            from .executors.local import LocalProcesses

            executor = LocalProcesses()
        self.executor = executor
        self._idle: queue.Queue[Worker] = queue.Queue()
        self._all: list[Worker] = []
        #: the workers known to be up (their ``ready`` answered)
        self._up: set[int] = set()
        self._lock = threading.Lock()
        self._cache: OrderedDict[str, FieldErrors] = OrderedDict()
        self._cache_size = cache_size
        self._closed = False
        #: processes still to start (``lazy``: when first needed)
        self._unstarted = processes
        if not lazy:
            self._start()

    def _start(self) -> None:
        with self._lock:
            n, self._unstarted = self._unstarted, 0
        for _ in range(n):
            self._add()

    def _add(self) -> None:
        # pdeathsig off: replacements start from the API's pool threads, which may end
        worker = self.executor.start(CheckWorker, (asdict(self.limits),),
                                     Resources(cpus=1.0, pdeathsig=False), "model-check")
        with self._lock:
            self._all.append(worker)
        self._idle.put(worker)

    def _drop(self, worker: Worker) -> None:
        worker.kill()
        with self._lock:
            if worker in self._all:
                self._all.remove(worker)
            self._up.discard(id(worker))
        if not self._closed:
            self._add()  # its replacement starts importing now

    def close(self) -> None:
        self._closed = True
        with self._lock:
            workers = list(self._all)
        for worker in workers:
            worker.kill()

    def check(self, model: ModelText) -> FieldErrors:
        """The model's errors (under its own fields, see :func:`check_model`); [] when the
        service can load it. CheckerBusyError when no checker process came free in time."""
        reasons = [] if len(model.text) <= self.limits.max_bytes else [
            (model.field, f"the model is {len(model.text)} characters; at most "
                          f"{self.limits.max_bytes} are accepted")]
        if reasons:
            return reasons
        key = model.key()
        with self._lock:
            if key in self._cache:
                self._cache.move_to_end(key)
                return list(self._cache[key])
        errors = self._run(model)
        with self._lock:
            self._cache[key] = errors
            while len(self._cache) > self._cache_size:
                self._cache.popitem(last=False)
        return list(errors)

    def call(self, task: Task, time_limit: float | None = None) -> Any:
        """The value of ``task`` run in a checker process, under the checker's memory limit
        and its time limit (or ``time_limit`` [s]): TaskLimitError past them (the process
        is replaced), TaskError when the task raised, CheckerBusyError when no checker
        process came free."""
        limit = self.limits.time_limit if time_limit is None else time_limit
        worker = self._take()
        try:
            status, value, detail = worker.call("task", task).result(timeout=limit)
        except TimeoutError:
            reason = f"it took longer than the {limit:g} s allowed"
        except (WorkerLostError, WorkerError):
            reason = (f"its process died (beyond its {self.limits.memory_bytes >> 20} MB "
                      "memory limit?)")
        else:
            self._idle.put(worker)
            if status == "ok":
                return value
            if status == "error":
                raise TaskError(str(value), detail)
            raise TaskLimitError(detail)
        log.warning("%s task refused: %s", task.name, reason)
        self._drop(worker)
        raise TaskLimitError(reason)

    def _take(self) -> Worker:
        """An idle checker worker, up and ready (a dead one is replaced)."""
        if self._unstarted:
            self._start()
        for _ in range(3):
            try:
                worker = self._idle.get(timeout=self.START_TIMEOUT)
            except queue.Empty as exc:
                raise CheckerBusyError("every model checker is busy") from exc
            if id(worker) in self._up:
                return worker
            try:
                worker.call("ready").result(timeout=self.START_TIMEOUT)
            except (TimeoutError, WorkerLostError, WorkerError) as exc:
                log.warning("model checker %s gone (%s); replacing it", worker.where(), exc)
                self._drop(worker)
                continue
            with self._lock:
                self._up.add(id(worker))
            return worker
        raise CheckerBusyError("the model checkers do not start")

    def _run(self, model: ModelText) -> FieldErrors:
        worker = self._take()
        t0 = time.monotonic()
        try:
            errors: FieldErrors = worker.call("check", model).result(
                timeout=self.limits.time_limit)
        except TimeoutError:
            reason = (f"loading the model took longer than the {self.limits.time_limit:g} s "
                      "allowed")
        except (WorkerLostError, WorkerError):
            reason = (f"the model checker died loading the model (beyond its "
                      f"{self.limits.memory_bytes >> 20} MB memory limit?)")
        else:
            self._idle.put(worker)
            log.info("model %s checked in %.3f s: %s", model.where, time.monotonic() - t0,
                     "ok" if not errors else errors[0][1])
            return errors
        log.warning("model %s refused: %s", model.where, reason)
        self._drop(worker)
        return [(model.field, reason)]


# -- the models of a request -------------------------------------------------------------------

def _walk(value: Any, where: str) -> Iterator[tuple[str, BaseModel]]:
    if isinstance(value, BaseModel):
        yield where, value
        for name in type(value).model_fields:
            yield from _walk(getattr(value, name), f"{where}.{name}" if where else name)
    elif isinstance(value, list | tuple):
        for i, item in enumerate(value):
            yield from _walk(item, f"{where}[{i}]")


def request_models(request: BaseModel) -> list[ModelText]:
    """Every model text a request carries, wherever it is (a one-finger request's
    ``finger.urdf``, a manipulation request's ``fingers[i].finger.urdf``, ...): any part of
    the request with a ``urdf`` (or, later, ``mjcf``) text."""
    out = []
    for where, part in _walk(request, ""):
        for kind in LOADERS:
            text = getattr(part, kind, None)
            if isinstance(text, str):
                params: tuple[tuple[str, Any], ...] = (
                    ("tip_frame", getattr(part, "tip_frame", "fingertip")),)
                tips = getattr(part, "tips", None)
                if tips is not None:  # a whole hand's model
                    params = (("tips", json.dumps([t.model_dump(mode="json")
                                                   for t in tips])),)
                out.append(ModelText(where, kind, kind, text, params))
    return out
