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

__all__ = ["FINGERS", "FingerCache", "Planners", "hand_finger_name", "urdf_errors"]


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

    def hand(self, spec: HandModel) -> Hand:
        """The built-in hand of a request (its fingers on the request's mounts);
        ProblemError naming ``hand.mounts`` when they do not fit the hand."""
        mounts = None if spec.mounts is None else tuple(
            (tuple(m.position), tuple(m.rotation)) for m in spec.mounts)
        key = (spec.builtin, mounts)
        with self.lock:
            cached = self._hands.get(key)
            if cached is not None:
                return cached
            hand = _load_hand(spec)
            self._make_room(len(hand.fingers))
            self._hands[key] = hand
            return hand


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
        return load_hand(spec.builtin, mounts=mounts)
    except ValueError as exc:  # the mounts do not fit the hand
        raise ProblemError([("hand.mounts" if spec.mounts is not None else "hand.builtin",
                             str(exc))]) from exc


def hand_finger_name(hand: Hand, index: int) -> str:
    """The hand's name of its finger ``index`` (its tip frame's prefix: f1, f2, ...)."""
    return hand.tip_frames[index].removesuffix("_fingertip")


#: The fingers (and finger planners) of this process.
FINGERS = FingerCache()


@dataclass(frozen=True)
class Planners:
    """What a plan is made with: the ball-on-palm planner (None: the core's process-wide
    one) and the fingers, hands and finger planners (default: this process's), each with
    its cache of built NLPs."""

    palm: BallOnPalmPlanner | None = None
    fingers: FingerCache = field(default_factory=lambda: FINGERS)
