"""The wire contract's results: one model per planner (``planner`` tells them apart) on
one base (:class:`PlanResultBase`), their trajectories, certificates and statistics (each
planner's on :class:`CertificateBase`, :class:`StatsBase`), and the ``collocation`` block a
later request's ``warm_start`` takes.

Import from :mod:`dexroll_client.models` (it re-exports everything).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Literal

from pydantic import Discriminator, Field, Tag

from dexroll_client.common import NlpPointModel, _planner_of, _Response
from dexroll_client.gait import GaitResultModel
from dexroll_client.manipulation_trajectory import (
    ContactTrajectoryModel,
    FingerJointsModel,
    ManipulationTrajectoryModel,
)

__all__ = [
    "AnyPlanResult",
    "CertificateBase",
    "CertificateModel",
    "CollocationModel",
    "ContactChartModel",
    "ContactSamplesModel",
    "ContactTrajectoryModel",
    "DurationModel",
    "FieldError",
    "FingerCertificateModel",
    "FingerJointsModel",
    "FingerPlanResult",
    "FingerSamplesModel",
    "FingerStatsModel",
    "FingerTrajectoryModel",
    "GraspFingerModel",
    "GraspUsedModel",
    "JointTrajectoryModel",
    "JointTrajectoryPointModel",
    "ManipulationCertificateModel",
    "ManipulationResult",
    "ManipulationStatsModel",
    "ManipulationTrajectoryModel",
    "PlanResult",
    "PlanResultBase",
    "PlanSamplesModel",
    "PlanStatus",
    "RateBreakModel",
    "StatsBase",
    "StatsModel",
    "TrajectoryModel",
]

class PlanStatus(StrEnum):
    """Outcome of a plan (same values as ``ocp.solution.Status``)."""

    SOLVED = "solved"
    INACCURATE = "inaccurate"
    INFEASIBLE = "infeasible"
    ITERATION_LIMIT = "iteration_limit"
    TIME_LIMIT = "time_limit"
    NUMERICAL_ERROR = "numerical_error"
    INVALID_INPUT = "invalid_input"
    ERROR = "error"


Rows = list[list[float]]


class TrajectoryModel(_Response):
    """A plan sampled at times t; rows are samples. Palm frame, SI units."""

    t: list[float] = Field(description="sample times [s]")
    eta: Rows = Field(description="contact coordinates (x [m], y [m], u [rad], v [rad], "
                                  "psi [rad])")
    eta_dot: Rows = Field(description="rates of the contact coordinates ([m/s], [rad/s])")
    w: Rows = Field(description="palm contact velocity d/dt (x, y), the input [m/s]")
    rolling_velocity: Rows = Field(description="(omega_x, omega_y) of the palm relative to "
                                               "the object, palm contact frame [rad/s]")
    object_position: Rows = Field(description="object centre in the palm frame [m]")
    object_orientation_wxyz: Rows = Field(description="object orientation in the palm frame,"
                                                      " unit quaternion (w, x, y, z), w >= 0")
    contact_point: Rows = Field(description="contact point in the palm frame [m]")
    contact_normal: Rows = Field(description="palm outward normal at the contact (unit)")


TIMES_DESCRIPTION = ("the time [s] of each check's worst sample (checks along the "
                     "motion), e.g. where the largest slip is")
TOLERANCES_DESCRIPTION = "tolerance of each check (units as the checked quantity)"
FAILURES_DESCRIPTION = "checks that failed, with values"


class CertificateBase(_Response):
    """A plan's certificate, whichever its planner: the verdict (``passed``) on the returned
    trajectory, computed independently of the NLP from the core's typed checks (each with
    its name, worst value, tolerance and kind). Each planner's model then states the
    checks' worst values in its own layout (named fields on the palm, a ``values`` map
    with fingers), followed alike by ``tolerances``, ``times`` and ``failures``: these are
    declared by each model after its values (with the descriptions above) because a
    subclass's fields follow its base's on the wire, and every certificate keeps its
    published key order."""

    passed: bool


class CertificateModel(CertificateBase):
    """Physical validity of the returned trajectory (the plan's polynomials, as ``samples``
    gives them), computed independently of the NLP: slip, spin and height checked densely
    along it, its states compared with a re-integration of the inputs at the nodes and
    midpoints (docs/conventions.md)."""

    max_position_defect: float | None = Field(
        description="worst re-integration defect of x, y [m] (null: not computed)")
    max_angle_defect: float | None = Field(
        description="worst re-integration defect of u, v, psi [rad]")
    max_slip_speed: float | None = Field(
        description="worst speed of the object's contact point relative to the palm, along "
                    "the returned trajectory [m/s]")
    max_spin_rate: float | None = Field(
        description="worst object angular velocity about the contact normal [rad/s]")
    max_height_error: float | None = Field(
        description="worst gap/penetration between object and palm [m]")
    max_goal_error: float | None = Field(
        description="worst goal or via-point error of the re-integrated motion [m or rad]")
    n_samples: int = Field(description="samples checked along the returned trajectory")
    tolerances: dict[str, float] = Field(description=TOLERANCES_DESCRIPTION)
    times: dict[str, float] = Field(default_factory=dict, description=TIMES_DESCRIPTION)
    failures: list[str] = Field(description=FAILURES_DESCRIPTION)


BUILD_TIME_DESCRIPTION = "NLP construction time [s] (0 when cached)"


class StatsBase(_Response):
    """IPOPT's account of a plan, whichever its planner: its return status and iterations,
    then (each planner's model) the timings and counts that planner reports."""

    raw_status: str = Field(description="IPOPT's return status")
    iterations: int = Field(description="IPOPT iterations")


class StatsModel(StatsBase):
    iterations: int = Field(description="IPOPT iterations, all attempts and refinements")
    attempts: int = Field(description="initial guesses tried")
    build_time: float = Field(description=BUILD_TIME_DESCRIPTION)
    solve_time: float = Field(description="IPOPT and initial-guess time [s]")
    certificate_time: float = Field(description="certificate time [s]")
    objective: float = Field(description="control effort integral |w|^2 dt [m^2/s]")
    cache_hit: bool = Field(description="the NLP came from the structure cache")
    refinements: int = Field(description="grid refinements after the first solve")
    n_intervals: int = Field(description="collocation intervals of the returned plan")
    ipopt_time: float = Field(default=0.0, description="the IPOPT calls alone [s] (part of "
                                                       "`solve_time`)")


class FieldError(_Response):
    field: str = Field(description="dotted path of the offending field")
    reason: str


GOAL_ERROR_DESCRIPTION = "error of each goal/via-point coordinate [m or rad]"


class PlanResultBase(_Response):
    """A plan of any planner, or why there is none: what every result says first, in this
    order (each planner's model narrows ``planner``, ``stats`` and ``certificate`` to its
    own). The plan follows in the planner's own layout (its model's fields), and every
    model ends with the plan's ``chart_rotation`` and ``collocation`` block
    (:data:`CHART_DESCRIPTION`, :data:`COLLOCATION_DESCRIPTION`), declared by each model
    after its trajectories so that every result keeps its published key order.
    :data:`AnyPlanResult` tells the models apart by ``planner``."""

    planner: str = Field(description="the planner of the request")
    status: PlanStatus
    message: str
    errors: list[FieldError] = Field(default_factory=list)
    stats: StatsBase | None = None
    goal_error: dict[str, float] | None = Field(default=None,
                                                description=GOAL_ERROR_DESCRIPTION)
    certificate: CertificateBase | None = None


class CollocationModel(_Response):
    """A plan's states and inputs at its collocation points (nodes and midpoints), in the
    planner's own layout: what a later request's ``warm_start`` takes (pass this block as
    it is). Rows are samples; every column is named (SI units: m, rad; inputs m/s, rad/s).

    Column names, by planner:

    * ball_on_palm: states ``x, y, u, v, psi`` (the contact coordinates, as in ``initial``);
      inputs ``w_x, w_y`` (the palm contact velocity d/dt (x, y)).
    * one_finger (a palm and a fingertip named ``finger``): states ``palm.x, palm.y,
      palm.u, palm.v, palm.psi``, ``finger.x, finger.y, finger.u, finger.v, finger.psi``
      (the finger contact's (x_f, y_f, u_f, v_f, psi_f)), ``finger.q.<joint>`` for each
      joint; inputs ``palm.w_x, palm.w_y``, ``finger.w_u, finger.w_v`` (d/dt (u_f, v_f):
      the contact's motion over the ball), ``finger.q_dot.<joint>``.
    * manipulation: the object first: with a palm, ``palm.x ... palm.psi`` / inputs
      ``palm.w_x, palm.w_y``; without one, ``object.position.x, .y, .z`` (palm frame [m]),
      ``object.orientation.w, .x, .y, .z`` (quaternion, object to palm frame) / inputs
      ``object.velocity.x, .y, .z`` (d/dt position, palm frame [m/s]),
      ``object.angular_velocity_body.x, .y, .z`` (the object's angular velocity in the
      object's own frame [rad/s], unlike `trajectory.object_angular_velocity`, which is in
      the palm frame); then each fingertip in request order, by its contact name:
      ``<name>.x, <name>.y, <name>.u, <name>.v, <name>.psi``, ``<name>.q.<joint>`` /
      inputs ``<name>.w_u, <name>.w_v``, ``<name>.q_dot.<joint>``."""

    t: list[float] = Field(description="the collocation points' times [s], from 0, "
                                       "increasing")
    x: Rows = Field(description="the states, one row per time, columns `state_names` "
                                "[m, rad]")
    u: Rows = Field(description="the inputs, one row per time, columns `input_names` "
                                "[m/s, rad/s]")
    state_names: list[str] = Field(description="the name of each column of `x` (see the "
                                               "model's description for the layout)")
    input_names: list[str] = Field(description="the name of each column of `u`")
    nlp_point: NlpPointModel | None = Field(
        default=None, description="IPOPT's primal-dual point at this plan (null for the "
                                  "ball-on-palm planner, whose few iterations it would not "
                                  "shorten): a warm start of a request with the same NLP "
                                  "starts from it")


COLLOCATION_DESCRIPTION = (
    "the plan's states and inputs at its collocation points, every column named: pass it "
    "as a later request's `warm_start` (null: no plan, a greedy plan, or a non-finite last "
    "iterate)")


CHART_DESCRIPTION = (
    "the object's chart patch (rotation vector [rad]) in which this result's palm contact "
    "coordinates (u, v, psi) are given: the request's `object.chart_rotation`, or another "
    "that the planner chose because the plan rode the pole bound (`pole_margin`) of the "
    "request's (the same physical plan, restated; docs/conventions.md); null without a "
    "palm or a plan")

class PlanResult(PlanResultBase):
    """A ball-on-palm plan, or why there is none. ``grid``: the collocation points (nodes
    and midpoints); ``samples``: the request's ``sample_times``."""

    planner: Literal["ball_on_palm"] = Field(default="ball_on_palm",
                                             description="the planner of the request")
    stats: StatsModel | None = None
    certificate: CertificateModel | None = None
    grid: TrajectoryModel | None = None
    samples: TrajectoryModel | None = None
    chart_rotation: list[float] | None = Field(default=None, description=CHART_DESCRIPTION)
    collocation: CollocationModel | None = Field(default=None,
                                                 description=COLLOCATION_DESCRIPTION)


class FingerTrajectoryModel(_Response):
    """A one-finger plan at the collocation points (nodes and midpoints); rows are samples.
    Palm frame, SI units."""

    t: list[float] = Field(description="sample times [s]")
    eta_p: Rows = Field(description="palm contact coordinates (x [m], y [m], u [rad], "
                                    "v [rad], psi [rad])")
    eta_f: Rows = Field(description="finger contact coordinates (x_f [m], y_f [m], "
                                    "u_f [rad], v_f [rad], psi_f [rad])")
    eta_p_dot: Rows = Field(description="rates of the palm contact coordinates ([m/s], "
                                        "[rad/s])")
    eta_f_dot: Rows = Field(description="rates of the finger contact coordinates ([m/s], "
                                        "[rad/s])")
    q: Rows = Field(description="joint angles, in the order of `joint_names` [rad; m for a "
                                "prismatic joint]")
    q_dot: Rows = Field(description="joint rates [rad/s; m/s for a prismatic joint]")
    w_p: Rows = Field(description="palm contact velocity d/dt (x, y), an input [m/s]")
    w_f: Rows = Field(description="finger contact velocity over the ball d/dt (u_f, v_f), "
                                  "an input [rad/s]")
    object_position: Rows = Field(description="object centre in the palm frame [m]")
    object_orientation_wxyz: Rows = Field(description="object orientation in the palm "
                                                      "frame, unit quaternion (w, x, y, z), "
                                                      "w >= 0")
    fingertip_position: Rows = Field(description="origin of the fingertip (pad) frame in "
                                                 "the palm frame [m]")
    fingertip_orientation_wxyz: Rows = Field(description="fingertip (pad) frame orientation "
                                                         "in the palm frame, unit quaternion "
                                                         "(w, x, y, z), w >= 0")
    palm_contact_point: Rows = Field(description="palm/object contact point in the palm "
                                                 "frame [m]")
    finger_contact_point: Rows = Field(description="finger/object contact point in the "
                                                   "palm frame [m]")
    finger_contact_normal: Rows = Field(description="the object's outward normal at the "
                                                    "finger contact, palm frame (unit)")
    grasp_angles: Rows = Field(description="grasp angles (Phi_p, Phi_f) at the palm and "
                                           "finger contacts: angle between the object's "
                                           "normal there and the line joining the two "
                                           "contacts, 0 for an antipodal grasp [rad]")
    cone_margin: list[float] = Field(description="atan(mu) - max(Phi_p, Phi_f): positive "
                                                 "inside the friction cone [rad]")
    palm_contact_force: Rows | None = Field(
        default=None, description="the planned force the palm exerts on the object [N], palm "
                                  "frame; null without `forces` in the request")
    finger_contact_force: Rows | None = Field(
        default=None, description="the planned force the fingertip exerts on the object [N], "
                                  "palm frame; null without `forces`")
    joint_torques: Rows | None = Field(
        default=None, description="the finger's joint torques [N m] that exert the planned "
                                  "fingertip force and torsion (J^T (f; m) at the contact "
                                  "point) and hold its links against gravity when its model "
                                  "has inertias; null without `forces`")


class FingerCertificateModel(CertificateBase):
    """Physical validity of a one-finger plan's returned trajectory, computed
    independently of the NLP: checked densely along it, the finger placed by Pinocchio's
    forward kinematics at the returned joint angles, the inputs re-integrated."""

    values: dict[str, float] = Field(description="worst value of each check along the "
                                                 "returned trajectory (units as the "
                                                 "quantity: m, rad, m/s, rad/s)")
    tolerances: dict[str, float] = Field(description=TOLERANCES_DESCRIPTION)
    times: dict[str, float] = Field(default_factory=dict, description=TIMES_DESCRIPTION)
    failures: list[str] = Field(description=FAILURES_DESCRIPTION)


class FingerStatsModel(StatsBase):
    build_time: float = Field(description=BUILD_TIME_DESCRIPTION)
    solve_time: float = Field(description="IPOPT time [s]")
    refinements: int = Field(default=0, description="grid refinements after the first solve "
                                                    "(the certificate found the grid coarse)")


SAMPLES_DESCRIPTION = ("the plan at the request's `sample_times` or `sample_rate` (null "
                       "without them, or without a finite plan)")
JOINT_TRAJECTORY_DESCRIPTION = (
    "every finger's joints as a ROS 2 trajectory_msgs/JointTrajectory, at the request's "
    "`sample_times` or `sample_rate`, else at the collocation points (null without a "
    "finite plan, and for the greedy method)")


class FingerPlanResult(PlanResultBase):
    """A one-finger plan, or why there is none. ``trajectory``: the collocation points
    (nodes and midpoints)."""

    planner: Literal["one_finger"] = Field(default="one_finger",
                                           description="the planner of the request")
    stats: FingerStatsModel | None = None
    certificate: FingerCertificateModel | None = None
    joint_names: list[str] = Field(default_factory=list,
                                   description="the finger's joints, in the order of `q`")
    trajectory: FingerTrajectoryModel | None = None
    chart_rotation: list[float] | None = Field(default=None, description=CHART_DESCRIPTION)
    samples: PlanSamplesModel | None = Field(default=None, description=SAMPLES_DESCRIPTION)
    joint_trajectory: JointTrajectoryModel | None = Field(
        default=None, description=JOINT_TRAJECTORY_DESCRIPTION)
    collocation: CollocationModel | None = Field(default=None,
                                                 description=COLLOCATION_DESCRIPTION)


class DurationModel(_Response):
    """ROS 2's ``builtin_interfaces/Duration``."""

    sec: int = Field(description="whole seconds")
    nanosec: int = Field(ge=0, le=999_999_999, description="nanoseconds")


class JointTrajectoryPointModel(_Response):
    """ROS 2's ``trajectory_msgs/JointTrajectoryPoint`` (``t``: its time in seconds)."""

    positions: list[float] = Field(description="joint positions [rad; m for a prismatic "
                                               "joint], in the order of `joint_names`")
    velocities: list[float] = Field(description="their time derivatives [rad/s; m/s]")
    accelerations: list[float] = Field(description="their second time derivatives "
                                                   "[rad/s^2; m/s^2]")
    time_from_start: DurationModel
    t: float = Field(description="time_from_start in seconds")
    effort: list[float] | None = Field(
        default=None, description="joint torques [N m; N] that exert the planned contact "
                                  "forces (a plan with `forces`; else null)")
    touching: list[str] | None = Field(
        default=None, description="the fingertips touching the object at this time, by "
                                  "name (a gait's swinging fingertip is not)")


class RateBreakModel(_Response):
    """A node where the plan's inputs jump (a via-point of the paper's piecewise timing):
    positions continuous, two one-sided velocities."""

    t: float = Field(description="time [s]")
    velocities_before: list[float] = Field(description="joint velocities as the time is "
                                                       "approached from before")
    velocities_after: list[float] = Field(description="joint velocities from after (the "
                                                      "point at this time has these)")


class ActuatorModel(_Response):
    """One planned joint's actuator, as the hand file says."""

    joint: str = Field(description="the joint (the file's name)")
    actuator: str | None = Field(description="the actuator driving it (the file's name); "
                                             "null: none")
    kind: str = Field(description="'servo' (an affine bias: a position or velocity servo), "
                                  "'motor' (torque), or 'none' (not commanded)")
    gear: float = 1.0
    gain: float = 1.0
    bias: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0],
                              description="b0, b1, b2 of MuJoCo's affine bias")
    torque_range: list[float] | None = Field(
        default=None, description="the joint torque it can give [N m] (gear x forcerange)")
    ctrl_range: list[float] | None = None


class ActuatorTrajectoryModel(_Response):
    """What the hand file's own actuators must be commanded, at the joint trajectory's
    times, to make the plan's motion and its planned contact forces (docs/actuation.md):
    per joint, the torque it must get (the plan's joint torques plus the file's damping,
    Coriolis and inertia terms) and its actuator's control (a position servo: its set
    point, q + torque / kp; a motor: its torque over gear and gain)."""

    actuators: list[ActuatorModel]
    t: list[float] = Field(description="times [s] (the joint trajectory's)")
    torques: Rows = Field(description="per sample, each joint's needed torque [N m]")
    controls: list[list[float | None]] = Field(
        description="per sample, each actuator's control (null: the joint has none)")
    max_load: float = Field(description="the largest share of a torque limit needed (1: at "
                                        "the limit; 0 without limits)")
    notes: list[str] = Field(default_factory=list)


class JointTrajectoryModel(_Response):
    """Every finger's joints shaped like ROS 2's ``trajectory_msgs/JointTrajectory``: hand
    ``joint_names`` and ``points`` to a joint trajectory controller as they are. From the
    plan's returned polynomials (the trajectory the certificate checked): velocities are
    the time derivative of positions, accelerations that of velocities."""

    joint_names: list[str] = Field(description="every finger's joints (`<finger>/<joint>` "
                                               "where two fingers share a joint name)")
    points: list[JointTrajectoryPointModel]
    rate_breaks: list[RateBreakModel] = Field(default_factory=list,
                                              description="nodes where the velocities jump")


class ContactSamplesModel(_Response):
    """One contact at the sample times; rows are samples."""

    name: str = Field(description="'palm', or the fingertip's name")
    eta: Rows = Field(description="contact coordinates (as the trajectory's `eta`)")
    eta_dot: Rows = Field(description="their time derivatives ([m/s], [rad/s])")
    force: Rows | None = Field(default=None, description="the planned force on the object "
                                                         "[N], palm frame (a plan with "
                                                         "`forces`; else null)")


class FingerSamplesModel(_Response):
    """One finger at the sample times; rows are samples."""

    name: str = Field(description="the fingertip's name")
    joint_names: list[str] = Field(description="the finger's joints, in the order of `q`")
    q: Rows = Field(description="joint angles [rad; m for a prismatic joint]")
    q_dot: Rows = Field(description="their time derivatives [rad/s; m/s]")
    q_ddot: Rows = Field(description="their second time derivatives [rad/s^2; m/s^2]")
    joint_torques: Rows | None = Field(default=None, description="joint torques [N m] of "
                                                                 "the planned forces (a "
                                                                 "plan with `forces`)")


class PlanSamplesModel(_Response):
    """A plan with fingers at the request's ``sample_times`` (or ``sample_rate``): the
    returned polynomials (docs/conventions.md); rows are samples. Palm frame, SI units. A
    time on a rate break gets the outgoing rates."""

    t: list[float] = Field(description="sample times [s]")
    object_position: Rows = Field(description="object centre [m]")
    object_orientation_wxyz: Rows = Field(description="object orientation, unit quaternion "
                                                      "(w, x, y, z), w >= 0")
    contacts: list[ContactSamplesModel]
    fingers: list[FingerSamplesModel]


class ManipulationCertificateModel(FingerCertificateModel):
    """Physical validity of a manipulation plan's returned trajectory, computed
    independently of the NLP: the laws checked densely along it (no slip or spin at any
    contact, pads tangent to the object, closure with every finger placed by Pinocchio's
    forward kinematics, joint limits, force closure, tracking), its states against a
    re-integration of the inputs (CVODES) at the nodes and midpoints."""

    values: dict[str, float] = Field(description="worst value of each check along the "
                                                 "returned trajectory (units as the "
                                                 "quantity: m, rad, m/s, rad/s); keys name "
                                                 "the contact, e.g. max_slip_speed_<name>")


class ManipulationStatsModel(FingerStatsModel):
    iterations: int = Field(description="IPOPT iterations, refinements included")
    n_intervals: int = Field(description="collocation intervals of the returned plan")
    solver: str | None = Field(
        default=None, description="the NLP solver whose point is the plan: 'ipopt', "
                                  "'fatrop', or 'ipopt (fatrop: its status)' when IPOPT "
                                  "took over; null when not reported")
    primal_infeasibility: float | None = Field(
        default=None, description="the returned NLP point's largest violation of a "
                                  "constraint's or variable's bounds (the NLP's scaled "
                                  "units), whatever stopped the solver (converged, an "
                                  "iteration budget, the time limit); null when not "
                                  "evaluated")
    dual_infeasibility: float | None = Field(
        default=None, description="the returned NLP point's largest entry of the "
                                  "Lagrangian's gradient (grad f + J^T lam_g + lam_x); "
                                  "null when not evaluated")


class GraspFingerModel(_Response):
    """One finger of a searched grasp."""

    name: str = Field(description="the finger's contact name")
    searched: bool = Field(description="its joints were searched (false: given as "
                                       "`initial_q`)")
    q: list[float] = Field(description="its joint angles at t = 0 [rad; m for a slide "
                                       "joint]: `fingers[i].initial_q`")
    contact_point: list[float] = Field(description="the contact on the ball, palm frame [m]")
    contact_normal: list[float] = Field(description="the ball's outward normal there, palm "
                                                    "frame")
    tip_side: list[float] | None = Field(
        default=None, description="a capsule tip: the `side` of its chart (tip link frame) "
                                  "the plan used, the contact's direction across the cap's "
                                  "axis (`hand.tips[i].side`); null: the hand's own")
    reach: float | None = Field(
        default=None, description="how far [rad] this finger rolls toward the motion's "
                                  "turns from this grasp (up to the whole turn); null: not "
                                  "rolled")
    stop: str | None = Field(default=None, description="what stops that roll: a joint "
                                                       "limit, the cap's seam, singular")


class GraspUsedModel(_Response):
    """The initial grasp a request's `grasp` search found and the plan started from."""

    source: Literal["search"] = Field(default="search", description="where it came from")
    fingers: list[GraspFingerModel]
    reach: float | None = Field(default=None, description="the turn [rad] the grasp allows "
                                                          "toward the motion: the least "
                                                          "finger's reach")
    requested_turn: float = Field(description="the motion's turns in all [rad] (0: none)")
    closure: float = Field(
        description="how well the contacts oppose: for 3 or more, the least over "
                    "directions u of max_i n_i . u (> 0: the pushes alone balance any "
                    "force); for 2, minus the sine of the grasp angle")
    grasp_angle: float = Field(description="the planner's grasp angle Phi* [rad] (force "
                                           "closure: below atan(mu))")
    tip_gap: float = Field(description="the least distance between two fingertips [m]")
    candidates: list[int] = Field(description="candidate contacts found per finger")
    combinations: int = Field(description="combinations weighed")
    search_time: float = Field(description="the search's wall time [s]")
    rank: int = Field(default=0, description="which of the search's grasps, in its order of "
                                             "preference (0: the best; a gait that does not "
                                             "plan from it is tried from the next ones)")


class ContactChartModel(_Response):
    """The chart the fingertips' contact coordinates are on from time ``t``: the object
    point (u, v) and the contact angle psi of each fingertip's ``eta`` (trajectory,
    samples) are measured on it."""

    t: float = Field(description="from this time on [s]")
    chart: str = Field(description="the object's chart: its own latitude/longitude chart "
                                   "(named as the shape's surface, e.g. 'ellipsoid') or an "
                                   "egg's side chart ('ellipsoid_side': its poles on the "
                                   "egg's equator, its equator through the egg's ends)")
    patches: list[list[float]] = Field(description="each fingertip's patch of that chart, "
                                                   "a rotation vector [rad] (as "
                                                   "`fingers[i].chart_rotation`)")


class ManipulationResult(PlanResultBase):
    """A manipulation plan, or why there is none. ``trajectory``: the collocation points
    (nodes and midpoints)."""

    planner: Literal["manipulation"] = Field(default="manipulation",
                                             description="the planner of the request")
    stats: ManipulationStatsModel | None = None
    goal_error: dict[str, float] | None = Field(
        default=None, description="error of each palm goal/via-point coordinate [m or "
                                  "rad], e.g. 'palm.x'")
    certificate: ManipulationCertificateModel | None = None
    trajectory: ManipulationTrajectoryModel | None = None
    chart_rotation: list[float] | None = Field(default=None, description=CHART_DESCRIPTION)
    samples: PlanSamplesModel | None = Field(default=None, description=SAMPLES_DESCRIPTION)
    joint_trajectory: JointTrajectoryModel | None = Field(
        default=None, description=JOINT_TRAJECTORY_DESCRIPTION)
    collocation: CollocationModel | None = Field(default=None,
                                                 description=COLLOCATION_DESCRIPTION)
    actuator_trajectory: ActuatorTrajectoryModel | None = Field(
        default=None, description="the hand file's actuators' commands for this plan, at "
                                  "the joint trajectory's times (a hand of one file; null: "
                                  "fingers of their own)")
    grasp: GraspUsedModel | None = Field(
        default=None, description="the initial grasp the request's `grasp` search found "
                                  "(null: none was searched)")
    gait: GaitResultModel | None = Field(
        default=None, description="the gait's phases (a request with `gait`; null: one "
                                  "rolling plan)")
    contact_charts: list[ContactChartModel] | None = Field(
        default=None, description="the charts the fingertips' contact coordinates are on, "
                                  "in time order: an egg's side chart, or two when the "
                                  "contacts change chart inside the plan (a contact "
                                  "rolling where no one chart is regular); null: the "
                                  "request's charts throughout")


#: A plan of any planner, told apart by its ``planner`` field (results stored before it
#: existed are ball-on-palm plans).
AnyPlanResult = Annotated[
    Annotated[PlanResult, Tag("ball_on_palm")]
    | Annotated[FingerPlanResult, Tag("one_finger")]
    | Annotated[ManipulationResult, Tag("manipulation")],
    Discriminator(_planner_of),
]
