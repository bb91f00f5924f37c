"""A process's planners and their caches: the fingers, hands and finger planners
(:class:`FingerCache`), and the bundle a plan is made with (:class:`Planners`)."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dexroll_client.models import MAX_FINGER_JOINTS, FingerModelSpec, HandModel
from ocp.ball_on_palm import BallOnPalmPlanner
from ocp.geometry.surfaces import rotation_from_vector
from ocp.one_finger import OneFingerPlanner
from ocp.robots.finger import FingerModel, load_finger
from ocp.robots.hands import Hand, load_hand
from ocp.solve.planner import ManipulationPlanner
from ocp.spec.problem import ProblemError

__all__ = ["FINGERS", "FingerCache", "Planners", "hand_finger_name", "hand_model_errors",
           "load_hand_model", "urdf_errors"]


class FingerCache:
    """A process's finger models, hands and finger planners, kept together.

    The planners cache their NLPs per finger object, so the same request finger (or hand)
    must map to the same :class:`~ocp.robots.finger.FingerModel` objects from job to job (cached
    here by URDF text, tip frame, mount and pad size; hands by name and mounts) for its NLP
    to be reused. The one-finger planner and the manipulation planner share one NLP cache
    (the one-finger planner is the general one with one finger's data). With more than
    ``max_fingers`` distinct fingers (a hand's fingers count), the fingers, the hands and
    the planners (with the NLPs they hold for them) are dropped together and start afresh,
    which bounds the memory. Thread-safe (one lock for loading and checking).
    """

    def __init__(self, max_fingers: int = 16, compile_dir: Path | None = None,
                 background: bool = False) -> None:
        self.max_fingers = max_fingers
        #: where the finger planners compile and cache their NLPs (None: not compiled), and
        #: whether in a background thread while the virtual machine solves
        #: (:class:`ocp.solve.planner.ManipulationPlanner`)
        self.compile_dir = compile_dir
        self.background = background
        self.lock = threading.RLock()
        self._fingers: dict[tuple[Any, ...], FingerModel] = {}
        self._hands: dict[tuple[Any, ...], Hand] = {}
        self._grasps: dict[str, Any] = {}
        self._planner: OneFingerPlanner | None = None

    @property
    def planner(self) -> OneFingerPlanner:
        """The process's one-finger planner (its NLP cache lives as long as the fingers)."""
        with self.lock:
            if self._planner is None:
                self._planner = OneFingerPlanner(ManipulationPlanner(self.compile_dir,
                                                                     self.background))
            return self._planner

    @property
    def manipulation(self) -> ManipulationPlanner:
        """The process's manipulation planner (the one-finger planner's own)."""
        return self.planner.general

    def _count(self) -> int:
        return len(self._fingers) + sum(len(h.fingers) for h in self._hands.values())

    def _make_room(self, n: int) -> None:
        if self._count() + n > self.max_fingers:
            self._fingers.clear()
            self._hands.clear()
            self._planner = None  # its NLPs refer to the fingers just dropped

    @staticmethod
    def _key(spec: FingerModelSpec) -> tuple[Any, ...]:
        source = f"builtin:{spec.builtin or 'k3s'}" if spec.urdf is None else spec.urdf
        return (source, spec.tip_frame,
                None if spec.base_position is None else tuple(spec.base_position),
                None if spec.base_rotation is None else tuple(spec.base_rotation),
                spec.pad_half_size)

    def finger(self, spec: FingerModelSpec, where: str = "finger") -> FingerModel:
        """The finger of a request, whose ``where`` it is (a one-finger request's
        ``finger``, a manipulation request's ``fingers[i].finger``); ProblemError naming
        ``<where>.urdf`` or ``<where>.tip_frame`` when it cannot be loaded."""
        key = self._key(spec)
        with self.lock:
            cached = self._fingers.get(key)
            if cached is not None:
                return cached
            finger = _load(spec, where)
            self._make_room(1)
            self._fingers[key] = finger
            return finger

    def hand(self, spec: HandModel) -> Any:
        """The hand of a request: a built-in one (the two_finger and three_finger hands'
        fingers on the request's mounts: :class:`~ocp.robots.hands.Hand`), or a whole-hand
        model (the allegro, a URDF or MJCF with its tips:
        :class:`~ocp.robots.whole_hand.WholeHand`); ProblemError naming ``hand.mounts``,
        ``hand.urdf``/``hand.mjcf`` or ``hand.tips[i]...`` when it cannot be used."""
        mounts = None if spec.mounts is None else tuple(
            (tuple(m.position), tuple(m.rotation)) for m in spec.mounts)
        key = (spec.builtin, mounts, spec.urdf, spec.mjcf,
               None if spec.tips is None else spec.model_dump_json(include={"tips"}),
               None if spec.mount is None else spec.mount.model_dump_json())
        with self.lock:
            cached = self._hands.get(key)
            if cached is not None:
                return cached
            hand = _load_hand(spec) if spec.builtin in ("two_finger", "three_finger") \
                else load_hand_model(spec)
            self._make_room(len(hand.fingers))
            self._hands[key] = hand
            return hand


    def hand_with_sides(self, spec: HandModel,
                        sides: tuple[tuple[float, float, float] | None, ...]) -> Any:
        """The request's hand with its capsule tips' chart ``side`` s replaced where
        ``sides[i]`` is given (a searched grasp's: each contact on its chart's equator):
        the built-in allegro's, or a model's tips read from its geometry whose ``side`` the
        request left out (others keep theirs)."""
        if spec.builtin == "allegro":
            key: tuple[Any, ...] = ("allegro", "sides", sides)
            with self.lock:
                cached: Any = self._hands.get(key)
                if cached is None:
                    from ocp.robots.allegro import load_allegro

                    cached = load_allegro("urdf", sides)
                    self._make_room(len(cached.fingers))
                    self._hands[key] = cached
                return cached
        if spec.tips is None:
            return self.hand(spec)
        tips = [t.model_copy(update={"side": list(s)})
                if s is not None and t.surface is None and t.side is None else t
                for t, s in zip(spec.tips, sides, strict=False)]
        tips += spec.tips[len(tips):]
        return self.hand(spec.model_copy(update={"tips": tips}))

    def grasp(self, key: str, search: Any) -> Any:
        """A grasp search's outcome by its request's ``key`` (the search is deterministic:
        its request's POST check and its worker each run it once), ``search()`` when not
        kept; the last 32 are kept, a GraspNotFound too."""
        with self.lock:
            got = self._grasps.get(key)
        if got is None:
            try:
                got = search()
            except ValueError as exc:  # GraspNotFound: kept as the answer
                got = exc
            with self.lock:
                if len(self._grasps) >= 32:
                    self._grasps.pop(next(iter(self._grasps)))
                self._grasps[key] = got
        if isinstance(got, Exception):
            raise got
        return got


def _load(spec: FingerModelSpec, where: str) -> FingerModel:
    if spec.urdf is not None and not spec.urdf.lstrip().startswith("<"):
        # load_finger would read a file of that name: never for a request
        raise ProblemError([(f"{where}.urdf", "must be the URDF document itself (XML "
                                              "text)")])
    try:
        finger = load_finger(
            urdf=spec.urdf, tip_frame=spec.tip_frame,
            base_rotation=None if spec.base_rotation is None else
            rotation_from_vector(spec.base_rotation),
            base_position=spec.base_position,
            pad_half_size=spec.pad_half_size)
    except MemoryError:  # a model checker's memory limit: its own answer
        raise
    except Exception as exc:  # whatever a user's URDF does to the loader, it is the URDF's
        reason = str(exc) or type(exc).__name__
        field = f"{where}.tip_frame" if repr(spec.tip_frame) in reason else f"{where}.urdf"
        raise ProblemError([(field, reason)]) from exc
    if finger.nq > MAX_FINGER_JOINTS:
        raise ProblemError([(f"{where}.urdf", f"the finger has {finger.nq} joints; at most "
                                              f"{MAX_FINGER_JOINTS} are supported")])
    return finger


def urdf_errors(urdf: str, tip_frame: str = "fingertip") -> list[tuple[str, str]]:
    """What loading a finger from a URDF text finds wrong, under the fields ``urdf`` and
    ``tip_frame``; [] when it loads (what a model checker process runs once the text's
    tree passed its limits: :mod:`planner_service.models_check`)."""
    try:
        _load(FingerModelSpec(urdf=urdf, tip_frame=tip_frame), "finger")
    except ProblemError as exc:
        return [(field.removeprefix("finger."), reason) for field, reason in exc.errors]
    return []


def _load_hand(spec: HandModel) -> Hand:
    mounts = None if spec.mounts is None else [
        (rotation_from_vector(m.rotation), np.asarray(m.position, dtype=float))
        for m in spec.mounts]
    try:
        return load_hand(str(spec.builtin), mounts=mounts)
    except ValueError as exc:  # the mounts do not fit the hand
        raise ProblemError([("hand.mounts" if spec.mounts is not None else "hand.builtin",
                             str(exc))]) from exc


def hand_finger_name(hand: Any, index: int) -> str:
    """The hand's name of its finger ``index`` (its tip frame's prefix: f1, f2, ...; a
    whole hand's tip link without ``_tip``)."""
    if hasattr(hand, "tip_frames"):
        return str(hand.tip_frames[index].removesuffix("_fingertip"))
    return str(hand.tip_names[index].removesuffix("_tip"))


def _tip_surface(model: Any, where: str) -> Any:
    """The core's tip surface of a request's ``TipSurfaceModel``."""
    from ocp.geometry.tips import TipSurface, capsule_tip

    dims = tuple(float(d) for d in model.dimensions)
    if model.kind == "capsule":
        if model.axis is None:
            raise ProblemError([(f"{where}.axis", "a capsule needs its axis (out of the cap, "
                                                  "link frame)")])
        axis = np.asarray(model.axis, dtype=float)
        side = None if model.side is None else np.asarray(model.side, dtype=float)
        if np.linalg.norm(axis) < 1e-9:
            raise ProblemError([(f"{where}.axis", "must not be zero")])
        if side is None:
            side = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 * np.linalg.norm(axis) \
                else np.array([0.0, 1.0, 0.0])
        try:
            return capsule_tip(dims[0], model.position, axis, side,
                               dims[1] if len(dims) > 1 else 0.0)
        except ValueError as exc:
            raise ProblemError([(f"{where}.side", str(exc))]) from exc
    R = rotation_from_vector(model.rotation)
    return TipSurface(model.kind, dims, tuple(tuple(float(x) for x in r) for r in R),
                      (float(model.position[0]), float(model.position[1]),
                       float(model.position[2])))


def load_hand_model(spec: HandModel) -> Any:
    """The whole hand of a request (the built-in allegro, or a URDF or MJCF with its
    tips); ProblemError naming ``hand.<field>``."""
    from ocp.robots.allegro import load_allegro
    from ocp.robots.whole_hand import HandModelError, TipSpec, load_whole_hand

    if spec.builtin == "allegro":
        return load_allegro("urdf")
    fmt = "urdf" if spec.urdf is not None else "mjcf"
    text = spec.urdf if spec.urdf is not None else spec.mjcf
    assert text is not None and spec.tips is not None
    if not text.lstrip().startswith("<"):
        raise ProblemError([(f"hand.{fmt}", "must be the model document itself (XML text)")])
    tips = []
    for i, t in enumerate(spec.tips):
        surface = None if t.surface is None else _tip_surface(t.surface,
                                                              f"hand.tips[{i}].surface")
        tips.append(TipSpec(t.name, surface, None if t.side is None else
                            (float(t.side[0]), float(t.side[1]), float(t.side[2]))))
    mount_R = mount_p = None
    if spec.mount is not None:
        mount_R = rotation_from_vector(spec.mount.rotation)
        mount_p = np.asarray(spec.mount.position, dtype=float)
    try:
        hand = load_whole_hand(text, fmt, tips, mount_R, mount_p)
    except MemoryError:
        raise
    except HandModelError as exc:
        raise ProblemError([(f"hand.{fmt}" if f == "model" else f"hand.{f}", r)
                            for f, r in exc.errors]) from exc
    except Exception as exc:  # whatever a user's model does to the loader
        raise ProblemError([(f"hand.{fmt}", str(exc) or type(exc).__name__)]) from exc
    for i, f in enumerate(hand.fingers):
        if f.nq > MAX_FINGER_JOINTS:
            raise ProblemError([(f"hand.tips[{i}].name", f"the finger has {f.nq} joints; at "
                                                         f"most {MAX_FINGER_JOINTS} are "
                                                         "supported")])
    return hand


def hand_model_errors(text: str, fmt: str, tips: str) -> list[tuple[str, str]]:
    """What loading a whole hand's model text with these tips finds wrong, under the
    fields ``urdf``/``mjcf`` and ``tips[i]...`` (``tips``: the request's, as JSON); []
    when it loads (a model checker process runs it: :mod:`planner_service.models_check`)."""
    import json

    try:
        load_hand_model(HandModel.model_validate({fmt: text, "tips": json.loads(tips)}))
    except ProblemError as exc:
        return [(field.removeprefix("hand."), reason) for field, reason in exc.errors]
    return []


#: The fingers (and finger planners) of this process.
FINGERS = FingerCache()


@dataclass(frozen=True)
class Planners:
    """What a plan is made with: the ball-on-palm planner (None: the core's process-wide
    one) and the fingers, hands and finger planners (default: this process's), each with
    its cache of built NLPs."""

    palm: BallOnPalmPlanner | None = None
    fingers: FingerCache = field(default_factory=lambda: FINGERS)
