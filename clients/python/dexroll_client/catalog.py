"""The wire contract's catalog (``GET /v1/models``): the built-in objects, fingers and
hands, and the planners.

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

from typing import Any

from pydantic import Field

from dexroll_client.common import _Response

__all__ = ["FingerInfo", "HandFingerInfo", "HandInfo", "ModelCatalog", "ObjectInfo"]

class ObjectInfo(_Response):
    shape: str
    parameters: list[str] = Field(description="names of `object.dimensions`, in order [m]")
    description: str


class FingerInfo(_Response):
    name: str = Field(description="its `finger.builtin` name")
    tip_frame: str = Field(description="the pad frame")
    n_joints: int
    joint_names: list[str] = Field(default_factory=list, description="in the order of q")
    pad_half_size: float | None = Field(default=None, description="half the side of the "
                                                                  "square pad [m]")
    base_position: list[float] | None = Field(
        default=None, description="its default mount: origin of its base (the URDF root) in "
                                  "the palm frame [m] (give it as `finger.base_position` with "
                                  "this URDF as `finger.urdf` to get the same finger)")
    base_rotation: list[float] | None = Field(
        default=None, description="its default mount: rotation vector of its base in the "
                                  "palm frame [rad]")
    urdf: str = Field(description="the URDF document")


class HandFingerInfo(_Response):
    """One finger of a built-in hand (a manipulation request's ``fingers[].hand_finger``
    is its index)."""

    name: str = Field(description="the finger's name (a request's default contact name)")
    tip_frame: str = Field(description="the pad frame in the hand's URDF")
    n_joints: int
    joint_names: list[str] = Field(default_factory=list, description="in the order of q")
    pad_half_size: float | None = Field(default=None,
                                        description="half the side of the square pad [m] "
                                                    "(None: a round tip)")
    tip_surface: dict[str, Any] | None = Field(
        default=None, description="a round tip: its kind, dimensions [m] and the tip frame "
                                  "(rotation rows, offset [m]) in the tip link's frame")
    nominal_initial: list[float] | None = Field(
        default=None, description="a round tip: its contact coordinates in the nominal "
                                  "grasp (with `nominal_chart_rotation`)")
    base_position: list[float] = Field(description="its default mount: origin of its base "
                                                   "in the palm frame [m]")
    base_rotation: list[float] = Field(description="its default mount: rotation vector of "
                                                   "its base in the palm frame [rad]")
    nominal_q: list[float] | None = Field(
        default=None, description="joint angles of the hand's nominal grasp [rad] (the "
                                  "default `q_seed` of this finger)")
    nominal_chart_rotation: list[float] = Field(
        description="in the nominal grasp (the nominal ball, unrotated), the "
                    "`chart_rotation` [rad] that puts this finger's contact at "
                    "`initial` = all zeros (the pad's centre, on the patch's (0, 0))")


class HandInfo(_Response):
    """A built-in hand: fingers around a palm, and its nominal grasp of a ball held in the
    air (a manipulation request with ``initial_pose.position`` = ``nominal_object_position``,
    ``object.dimensions`` = [``nominal_radius``] and each finger's
    ``nominal_chart_rotation`` with all-zero ``initial`` coordinates grasps it so)."""

    name: str = Field(description="its `hand.builtin` name")
    n_fingers: int
    fingers: list[HandFingerInfo]
    nominal_object_position: list[float] = Field(description="centre of the nominal ball in "
                                                             "the palm frame [m]")
    nominal_radius: float = Field(description="radius of the nominal ball [m]")
    urdf: str = Field(description="the hand's URDF document (root link: the palm frame)")
    mjcf: str | None = Field(default=None, description="the same hand as an MJCF document, "
                                                       "when there is one")


class ModelCatalog(_Response):
    planners: list[str] = Field(description="values of a request's `planner`")
    objects: list[ObjectInfo]
    fingers: list[FingerInfo]
    hands: list[HandInfo] = Field(default_factory=list,
                                  description="built-in hands (a manipulation request's "
                                              "`hand.builtin`)")
