"""The contact kinds as CasADi models: a grasp is an object block and its fingertips.

* :class:`SupportContact` (:mod:`.support`): the object resting on a fixed flat surface
  (the palm);
* :class:`FreeObject` (:mod:`.free_object`): the object's pose as a state when nothing
  fixes it;
* :class:`FingertipContact` (:mod:`.fingertip`): a fingertip surface rolling on the object;
* :class:`FreeFingertip` (:mod:`.free_fingertip`): a fingertip off the object (its joints
  alone);
* :mod:`.base`: what they share (:class:`Contact`, :class:`ObjectBlock`,
  :class:`SymbolicGrasp`); :mod:`.palm_model`: the palm/object contact's named functions of
  the ball-on-palm formulation.

The support and the free object are *object blocks*: exactly one of them comes first in a
grasp and says where the object is; the fingertips follow (:func:`grasp_contacts`). The
kinds sit on ``geometry`` and ``robots`` (and the problem descriptions of ``spec``), below
the transcription.
"""

from __future__ import annotations

from typing import Any

from ocp.contacts.base import JOINT_LIMIT_MARGIN, Contact, ObjectBlock, SymbolicGrasp
from ocp.contacts.fingertip import FingertipContact
from ocp.contacts.free_fingertip import FreeFingertip
from ocp.contacts.free_object import FreeObject
from ocp.contacts.support import SupportContact
from ocp.geometry.surfaces import Surface

__all__ = ["JOINT_LIMIT_MARGIN", "Contact", "FingertipContact", "FreeFingertip", "FreeObject",
           "ObjectBlock", "SupportContact", "SymbolicGrasp", "grasp_contacts"]


def grasp_contacts(shape_surface: Surface, palm: bool, fingers: tuple[Any, ...]
                   ) -> tuple[Contact, ...]:
    """The contacts of a grasp structure, offsets set: the object block, then each
    fingertip."""
    obj: Contact = SupportContact(shape_surface) if palm else FreeObject(shape_surface)
    out: list[Contact] = [obj, *(FingertipContact(shape_surface, f, i)
                                 for i, f in enumerate(fingers))]
    x0 = u0 = 0
    for c in out:
        c.x0, c.u0 = x0, u0
        x0, u0 = x0 + c.nx, u0 + c.nu
    return tuple(out)
