"""The simulator's settings: the contact model, the controller and its gains, the grip,
and the tolerances a run passes against (docs/simulation.md states and explains each)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

__all__ = ["FORCE_CONTROLS", "MODES", "SimOptions", "Tolerances"]

#: 'servo': every joint follows the plan through a position servo (velocity feed-forward,
#: the grip's or the plan's torques as torque feed-forward), the object free;
#: 'kinematic': the joints are set to the plan at every step (a perfect controller), the
#: object free; 'replay': the joints and the object are both set to the plan (nothing is
#: simulated: the report's errors are zero by construction, its contact forces those of
#: the plan's own geometry).
MODES = ("servo", "kinematic", "replay")

#: 'off': the planned forces are fed forward only (J^T f); 'pi': contact-force feedback
#: on top as joint torques, per fingertip with a planned force; 'admittance': the same
#: feedback as a shift of the servo's set point along the contact normal (see
#: :class:`SimOptions`).
FORCE_CONTROLS = ("off", "pi", "admittance")


@dataclass(frozen=True)
class Tolerances:
    """A run passes when the object stays within ``position`` [m] and ``angle`` [rad] of
    the plan at every recorded time of the plan and no planned contact is lost for more
    than ``contact_loss`` [s] in all after the settling phase."""

    position: float = 1e-3
    angle: float = math.radians(2.0)
    contact_loss: float = 0.0


@dataclass(frozen=True)
class SimOptions:
    """How a plan is executed (the defaults are the ones docs/simulation.md measured).

    Contact model: ``condim`` 4 (tangential and torsional friction: a soft finger; 6 adds
    rolling friction ``rolling_friction`` [m], 3 is a point contact), elliptic friction
    cones with ``impratio``, ``noslip_iterations`` of MuJoCo's no-slip solver,
    ``torsional_friction`` [m] (the plan's when it states one), ``solref`` (time constant
    [s], damping ratio) of every contact, a step of ``timestep`` [s].

    Controller (``mode``, see :data:`MODES`): a joint-space PD servo per joint, stiffness
    ``kp`` [N m/rad] and damping ``kv`` [N m s/rad] (integrated implicitly), the plan's
    joint rates as velocity feed-forward; every moving link weighs ``link_mass`` [kg] and
    each joint has ``armature`` [kg m^2] (the finger models carry no inertias), gravity on
    the links compensated.

    Grip: the fingertips' references are moved ``squeeze`` [m] (None: the plan's own,
    ``ExecutionPlan.squeeze``, else :data:`DEFAULT_SQUEEZE`) into the object along the
    pad's normal, and each fingertip pushes with ``grip_force`` [N] along its normal as
    torque feed-forward (``J^T f``); a plan with its own forces or joint torques uses
    those instead of ``grip_force`` (``use_plan_forces``). The object weighs
    ``object_mass`` [kg] unless the plan states its mass (None: the plan's or the
    default); gravity is the plan's.

    Force control (``force_control``, see :data:`FORCE_CONTROLS`; None: the plan's own,
    ``ExecutionPlan.force_control``, else 'off'): with 'pi', each fingertip whose contact
    has a planned force measures its contact's normal force in MuJoCo (the sum over the
    fingertip's pad touching the object, at the end of the previous step), compares it
    with the planned normal force and pushes the difference back along the planned
    contact normal as joint torques ``J^T n u``, ``u`` a PI law: ``force_kp`` [N/N] times
    the error plus ``force_ki`` [1/s] times its integral, ``u`` clipped to
    ``±force_limit`` [N] and the integral held while clipped (anti-windup). The target
    is the planned normal force, but at least ``force_min`` [N] where the plan counts the
    contact as touching (activity 0.5 and up; from none at 0.25), the difference fed
    forward: 0.65 N, a margin over the planner's least normal force (0.5 N; a contact
    held at exactly that flickered off by fractions of a micrometre, docs/gait.md). The
    feedback is off while the fingertip is lifted (activity 0: its integral reset), full
    from activity 0.25 (the lift-off and approach) up, and ramps with the grip while
    settling. The servo and the
    squeeze stay as they are (the feedback adds to them); the report's notes say which
    ran.

    With 'admittance' (a gait's default) the same error (the same target, weight and
    ramps) moves the servo's set point instead of adding a torque: the fingertip's set
    point shifts along the planned normal into the object by ``d``, ``force_shift_ki``
    [m/(N s)] times the integral of the error, kept within [0, ``force_shift_limit``]
    [m] (it pushes in, never pulls out past the plan's own set point; reset while the
    fingertip is lifted); the joints by ``J^T n d / |J^T n|^2``, which moves the tip by
    ``d`` along the normal to first order. The floor's excess over the plan is fed
    forward as torque. Why: a torque pushes against the stiff servo (at ``kp`` = 200
    N m/rad and ``force_limit`` 3 N a fingertip moves some 25 um), so a contact the
    others hold the object 30 um away from stays lost under 'pi'; a shifted set point
    closes it. The shift's bound keeps the fingers from pushing the object around (at
    0.5 mm a 90 deg gait drifted 0.7 mm and 2.2 deg).

    Before the plan's t = 0 the hand holds the initial grasp for ``settle`` [s]: the grip
    ramps up with the object held in place during the first half, then the object is let
    go. Errors and contact losses count from t = 0. ``record_every`` steps are recorded
    in the report's time series.
    """

    mode: str = "servo"
    timestep: float = 5e-4
    condim: int = 4
    impratio: float = 10.0
    noslip_iterations: int = 3
    torsional_friction: float | None = None
    rolling_friction: float = 0.0
    solref: tuple[float, float] = (0.004, 1.0)
    kp: float = 200.0
    kv: float = 2.0
    link_mass: float = 0.02
    armature: float = 1e-3
    squeeze: float | None = None
    force_control: str | None = None
    force_kp: float = 0.1
    force_ki: float = 400.0
    force_limit: float = 3.0
    force_min: float = 0.65
    force_shift_ki: float = 2e-2
    force_shift_limit: float = 2e-4
    grip_force: float = 1.0
    use_plan_forces: bool = True
    object_mass: float | None = None
    #: On the user's model (``sim.user_model``): the mass [kg] given to each moving body of
    #: the file left without one once its mesh geoms are removed (the mass came from the
    #: meshes' volume, files the scene never reads). None: such a file is refused, naming
    #: the bodies.
    model_link_mass: float | None = None
    settle: float = 0.2
    record_every: int = 10
    tolerances: Tolerances = Tolerances()

    #: the squeeze [m] when neither the options nor the plan (``ExecutionPlan.squeeze``)
    #: give one
    DEFAULT_SQUEEZE = 0.5e-3

    def squeeze_for(self, plan: Any) -> float:
        """The squeeze [m] for ``plan``: the options', else the plan's own, else
        :data:`DEFAULT_SQUEEZE`."""
        if self.squeeze is not None:
            return float(self.squeeze)
        own = getattr(plan, "squeeze", None)
        return self.DEFAULT_SQUEEZE if own is None else float(own)

    def force_control_for(self, plan: Any) -> str:
        """The force control for ``plan``: the options', else the plan's own, else
        'off'."""
        if self.force_control is not None:
            return self.force_control
        own = getattr(plan, "force_control", None)
        return "off" if own is None else str(own)

    @property
    def feedback(self) -> bool:
        """Whether contact-force feedback is asked ('pi' or 'admittance')."""
        return self.force_control not in (None, "off")

    def resolved(self, plan: Any) -> SimOptions:
        """These options for ``plan``, its squeeze (:meth:`squeeze_for`) and force control
        (:meth:`force_control_for`) filled in."""
        return replace(self, squeeze=self.squeeze_for(plan),
                       force_control=self.force_control_for(plan))

    #: torsional friction [m] when neither the options nor the plan give one: the
    #: torque about the normal a contact resists per newton of normal force
    DEFAULT_TORSIONAL = 0.005

    def check(self) -> None:
        """ValueError naming the first setting out of range."""
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, not {self.mode!r}")
        if not 1e-5 <= self.timestep <= 1e-2:
            raise ValueError("timestep must be within [1e-5, 1e-2] s")
        if self.condim not in (3, 4, 6):
            raise ValueError("condim must be 3, 4 or 6")
        for name in ("impratio", "kp"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive")
        if self.force_control is not None and self.force_control not in FORCE_CONTROLS:
            raise ValueError(f"force_control must be one of {FORCE_CONTROLS} or None, "
                             f"not {self.force_control!r}")
        if self.squeeze is not None and not (math.isfinite(self.squeeze) and
                                             self.squeeze >= 0):
            raise ValueError("squeeze must be finite and >= 0")
        for name in ("kv", "grip_force", "settle", "link_mass", "armature",
                     "rolling_friction", "force_kp", "force_ki", "force_limit",
                     "force_min", "force_shift_ki", "force_shift_limit"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and >= 0")
        if self.model_link_mass is not None and not (math.isfinite(self.model_link_mass)
                                                     and self.model_link_mass > 0):
            raise ValueError("model_link_mass must be finite and > 0 kg")
        if self.noslip_iterations < 0 or self.record_every < 1:
            raise ValueError("noslip_iterations >= 0 and record_every >= 1")
        if self.solref[0] < 2 * self.timestep:
            raise ValueError("solref's time constant must be at least two timesteps")

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["solref"] = list(self.solref)
        return out

    @staticmethod
    def from_dict(raw: dict[str, Any]) -> SimOptions:
        """Options from a dict (unknown keys: ValueError; ``tolerances`` a dict)."""
        known = {f.name for f in fields(SimOptions)}
        unknown = set(raw) - known
        if unknown:
            raise ValueError(f"unknown simulation options: {sorted(unknown)}")
        values = dict(raw)
        if isinstance(values.get("tolerances"), dict):
            values["tolerances"] = Tolerances(**values["tolerances"])
        if "solref" in values:
            a, b = values["solref"]
            values["solref"] = (float(a), float(b))
        options = SimOptions(**values)
        options.check()
        return options
