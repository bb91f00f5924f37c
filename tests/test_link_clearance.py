"""The whole hand's links against the object and each other (issue 37, item 4:
``ocp/robots/collision.py``), on ``examples/own_hand.xml`` (ours, in the Menagerie's
style: box palm, capsule links, capsule tips, visual meshes whose files are absent,
``<exclude>`` of the palm and the finger bases).

Laws: every distance reported is MuJoCo's own (``mj_geomDistance``) for that pair; no
pair MuJoCo would not collide (a body and its parent, an ``<exclude>``, a visual mesh) is
ever reported; a fingertip touching the object is left out only while its contact is
active; a grasp whose links enter each other or the ball is refused naming the bodies;
the grasp search and the certificate keep the links clear."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import nominal_turn

mujoco = pytest.importorskip("mujoco")

from ocp.robots.allegro import NOMINAL_OBJECT_POSITION, NOMINAL_Q, NOMINAL_RADIUS  # noqa: E402
from ocp.robots.collision import LINK_CLEARANCE, WINDOW, collision_text  # noqa: E402
from ocp.robots.first_grasp import GRASP_LINK_CLEARANCE  # noqa: E402
from ocp.robots.whole_hand import TipSpec, load_whole_hand  # noqa: E402

OWN = (Path(__file__).resolve().parents[1] / "examples" / "own_hand.xml").read_text()
TIPS = ("ff_tip", "mf_tip", "rf_tip", "th_tip")
BODY = re.compile(r"body '([^']+)' \(geom (\d+)\)")


@pytest.fixture(scope="module")
def hand():
    return load_whole_hand(OWN, "mjcf", [TipSpec(t) for t in TIPS])


def _names(hand):
    return [n for f in hand.fingers for n in f.joint_names]


def _at(hand, q, touching=None, centre=NOMINAL_OBJECT_POSITION):
    q = np.atleast_2d(q)
    n = len(q)
    return hand.collision([0, 1, 2, 3]).least(
        "sphere", (NOMINAL_RADIUS,), _names(hand), q, np.tile(np.eye(3), (n, 1, 1)),
        np.tile(np.asarray(centre, dtype=float), (n, 1)), touching)


def _turn(text, **extra):
    """A 0.1 rad turn about the palm's z of the nominal grasp on the hand ``text``."""
    from planner_service.planners import REQUEST

    return REQUEST.validate_python(nominal_turn(text, list(TIPS), **extra))


def _random_q(hand, n, seed=0):
    rng = np.random.default_rng(seed)
    lo = np.concatenate([f.lower for f in hand.fingers])
    hi = np.concatenate([f.upper for f in hand.fingers])
    return lo + rng.random((n, lo.size)) * (hi - lo)


def test_distances_are_mujocos_own_for_each_pair(hand):
    """Over random joint vectors (the ball far away), every pair nearer than the clearance
    is at MuJoCo's ``mj_geomDistance`` for those two geoms."""
    hc = hand.collision([0, 1, 2, 3])
    mj, d = hc._model("sphere", (NOMINAL_RADIUS,))[:2]
    addr = hc.joint_address("sphere", (NOMINAL_RADIUS,), _names(hand))
    seen = 0
    for q in _random_q(hand, 40):
        got = _at(hand, q, centre=(1.0, 1.0, 1.0))
        d.qpos[:] = mj.qpos0
        d.qpos[addr] = q
        d.qpos[-7:-4] = hc.mount[0].T @ (np.array([1.0, 1.0, 1.0]) - hc.mount[1])
        mujoco.mj_kinematics(mj, d)
        for (a, b), dist in got.near:
            g1, g2 = int(BODY.search(a).group(2)), int(BODY.search(b).group(2))
            exact = mujoco.mj_geomDistance(mj, d, g1, g2, WINDOW, None)
            assert dist == pytest.approx(exact, abs=1e-6)
            seen += 1
    assert seen > 0  # random hands do put links into each other


def test_pairs_mujoco_would_not_collide_are_never_reported(hand):
    """A body and its parent, the file's ``<exclude>`` pairs and visual mesh geoms never
    appear, however the joints are set."""
    hc = hand.collision([0, 1, 2, 3])
    mj = hc._model("sphere", (NOMINAL_RADIUS,))[0]
    excluded = {frozenset(p) for p in re.findall(r'<exclude body1="([^"]+)" body2="([^"]+)"',
                                                 OWN)}
    assert excluded
    for q in _random_q(hand, 60, seed=1):
        for (a, b), _ in _at(hand, q, centre=(1.0, 1.0, 1.0)).near:
            ga, gb = int(BODY.search(a).group(2)), int(BODY.search(b).group(2))
            ba, bb = int(mj.geom_bodyid[ga]), int(mj.geom_bodyid[gb])
            assert int(mj.body_parentid[ba]) != bb and int(mj.body_parentid[bb]) != ba
            assert frozenset((BODY.search(a).group(1), BODY.search(b).group(1))) not in excluded
            for g in (ga, gb):
                assert mj.geom_contype[g] or mj.geom_conaffinity[g]
    # the visual meshes are there, inert
    assert "mesh" in OWN and 'contype="0"' in collision_text(OWN)


def test_a_touching_fingertip_is_left_out_only_while_it_touches(hand):
    q = np.concatenate(NOMINAL_Q)
    held = _at(hand, q)
    assert held.passed, held.describe()
    lifted = _at(hand, q, touching=np.array([[False, True, True, True]]))
    assert lifted.value < LINK_CLEARANCE
    assert any("the object" in pair and "ff_tip" in " ".join(pair) for pair, _ in lifted.near)
    assert lifted.fingers == (0,)


def test_a_link_in_the_ball_is_refused_naming_the_bodies():
    """A file whose index medial link carries a fat collision sphere reaching into the ball
    at the nominal grasp: the request is a 422 naming the index finger's joints, the
    bodies and the depth."""
    from planner_service.planners import ProblemError
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.manipulation import manipulation_problem

    fat = OWN
    i = fat.index('<body name="ff_medial"')
    j = fat.index(">", i) + 1
    fat = fat[:j] + '<geom name="fat" type="sphere" size="0.03" pos="0.02 0 0.02"/>' + fat[j:]
    req = _turn(fat)
    with pytest.raises(ProblemError) as exc:
        manipulation_problem(req, FingerCache())
    fields = dict(exc.value.errors)
    assert "fingers[0].initial_q" in fields, exc.value.errors
    reason = fields["fingers[0].initial_q"]
    assert "'ff_medial' (geom 'fat')" in reason and "mm into" in reason


def test_the_search_keeps_links_clear_along_the_rolled_turn(hand):
    """first_grasp with the hand's links: the grasp it takes keeps them the search's
    clearance from the ball and each other, at the grasp and along the rolled turn."""
    from ocp.robots.first_grasp import _Turn, first_grasp

    seen: list[float] = []

    def clear(q):
        got = _at(hand, q)
        seen.append(got.value)
        return got

    found = first_grasp(hand.fingers, NOMINAL_OBJECT_POSITION, NOMINAL_RADIUS,
                        [_Turn(np.array([0.0, 0.0, 1.0]), 0.2)], mu=1.0, samples=300,
                        clear=clear)
    assert seen
    q = np.concatenate([np.asarray(ct.q) for ct in found.contacts])
    assert _at(hand, q).value >= GRASP_LINK_CLEARANCE


def test_a_certified_plan_states_its_links_clearance():
    """A roll on the file's own hand: its certificate has ``min_link_clearance`` (physics,
    at least 0.5 mm), MuJoCo's least distance over the plan's samples."""
    from planner_service.planners import solve

    req = _turn(OWN, n_intervals=10)
    result = solve(req)[0]
    assert result.status.value == "solved", result.message
    assert all(p.touching == ["ff", "mf", "rf", "th"] for p in result.joint_trajectory.points)
    values = result.certificate.values
    assert values["min_link_clearance"] >= LINK_CLEARANCE
    assert result.certificate.tolerances["min_link_clearance"] == LINK_CLEARANCE


def test_a_gait_does_not_roll_a_grasp_whose_links_are_too_close() -> None:
    """ocp.gait.planner's look ahead (the fingers' rolled motion, as for the tips' gaps):
    with a link already within MIN_ROLL_LINK_CLEARANCE of the ball the roll is cut at
    once, and the gait's reason names the link."""
    import dataclasses

    from ocp.gait.planner import MIN_ROLL_LINK_CLEARANCE, _roll_ahead, _too_close
    from planner_service.planners.cache import FingerCache
    from planner_service.planners.manipulation import manipulation_problem

    req = _turn(OWN, forces={"mass": 0.05})
    problem = manipulation_problem(req, FingerCache())
    qs = tuple(np.asarray(q, dtype=float) for q in NOMINAL_Q)
    centre = np.asarray(NOMINAL_OBJECT_POSITION, dtype=float)
    axis = np.array([0.0, 0.0, 1.0])
    clear = _roll_ahead(problem, qs, centre, NOMINAL_RADIUS, axis, 0.1)
    assert clear.close == "" and clear.apart == pytest.approx(0.1)
    i = OWN.index('<body name="ff_medial"')
    j = OWN.index(">", i) + 1
    fat = OWN[:j] + '<geom name="fat" type="sphere" size="0.03" pos="0.02 0 0.02"/>' + OWN[j:]
    near = load_whole_hand(fat, "mjcf", [TipSpec(t) for t in TIPS]).collision([0, 1, 2, 3])
    ahead = _roll_ahead(dataclasses.replace(problem, collision=near), qs, centre,
                        NOMINAL_RADIUS, axis, 0.1)
    assert ahead.apart == 0.0 and ahead.need >= MIN_ROLL_LINK_CLEARANCE
    assert "'ff_medial' (geom 'fat')" in ahead.close
    why = _too_close(ahead.need, 0.0, math.pi / 2, axis, ahead.close)
    assert why.startswith("the hand's links come within") and "'fat'" in why


def test_a_swings_obstacles_are_the_geoms_mujoco_collides_with_its_tip(hand) -> None:
    """HandCollision.obstacles: for the middle fingertip, the geoms of the other fingers'
    links and the palm that MuJoCo would collide with it (never its own chain's, the
    other tips' or the excluded), a box as capsules along its longest axis that together
    bound it: its corners and random points of it are each inside one of them."""
    hc = hand.collision([0, 1, 2, 3])
    q = np.concatenate(NOMINAL_Q)
    got = hc.obstacles("sphere", (NOMINAL_RADIUS,), _names(hand), q, 1)
    bodies = {BODY.search(n).group(1) for n, _ in got}
    assert bodies and not any(b.startswith("mf_") for b in bodies)
    assert not bodies & {"ff_tip", "rf_tip", "th_tip"}
    assert "ff_medial" in bodies and "palm" in bodies
    mj, d = hc._model("sphere", (NOMINAL_RADIUS,))[:2]
    from itertools import product

    from ocp.geometry.bodies import point_segment_distance

    d.qpos[:] = mj.qpos0
    d.qpos[hc.joint_address("sphere", (NOMINAL_RADIUS,), _names(hand))] = q
    mujoco.mj_kinematics(mj, d)
    capsules: dict[int, list] = {}
    for name, seg in got:
        g = int(BODY.search(name).group(2))
        if int(mj.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_BOX):
            capsules.setdefault(g, []).append(seg)
    assert capsules  # the palm's
    rng = np.random.default_rng(4)
    for g, segs in capsules.items():  # the box's corners and points of it: in a capsule
        R, c = d.geom_xmat[g].reshape(3, 3), d.geom_xpos[g]
        points = [np.array(signs) for signs in product((-1.0, 1.0), repeat=3)]
        points += list(rng.uniform(-1.0, 1.0, (50, 3)))
        for u in points:
            x = c + R @ (u * mj.geom_size[g])
            assert min(float(point_segment_distance(x, a, b)) - r for a, b, r in segs) \
                <= 1e-12
    near = hc.obstacles("sphere", (NOMINAL_RADIUS,), _names(hand), q, 1,
                        near=(np.asarray(NOMINAL_OBJECT_POSITION), NOMINAL_RADIUS + 0.005))
    assert len(near) < len(got)


def test_a_gait_whose_rolls_are_cut_too_short_is_refused_at_once_saying_why() -> None:
    """A gait's fingertips return to its grasp after each roll, so a roll cut to 1.9 deg
    by the hand's links stays so: 40 rolls cannot make 90 deg, said before any NLP."""
    from ocp.gait.planner import RollAhead, _too_few

    ahead = RollAhead(math.radians(10.0), "", "", math.radians(1.9), 1e-3,
                      "body 'mf_distal' (geom 19) 0.912 mm from body 'rf_distal' (geom 29)")
    why = _too_few(math.radians(1.9), 40, math.pi / 2, ahead)
    assert why == ("each roll from this grasp is cut to 1.9 deg (the hand's links come "
                   "within 1.00 mm (body 'mf_distal' (geom 19) 0.912 mm from body "
                   "'rf_distal' (geom 29))): 40 more rolls (max_rolls) cannot turn the "
                   "remaining 90.0 deg")
    stopped = RollAhead(math.radians(2.0), "th", "joint limit (thj0)", math.radians(10.0),
                        5e-4)
    assert "finger 'th' stops (joint limit (thj0))" in _too_few(math.radians(1.8), 40,
                                                                math.pi / 2, stopped)
    halved = _too_few(math.radians(1.8), 40, math.pi / 2, stopped,
                      "halved 2 time(s) after gait step 1: the swing of finger 'mf' was not "
                      "found")
    assert "cut to 1.8 deg (halved 2 time(s) after gait step 1: the swing of finger 'mf'" \
        in halved


def test_every_shapes_geom_is_collided_as_mujoco_reads_it(hand):
    """The clearance model gets each object shape's own geom (tests/test_shapes.py):
    an ellipsoid of revolution and a three-axis one with equal semi-axes are the ball
    (the model once wrote the first's size as 'a c', which MuJoCo refuses; MuJoCo
    collides an ellipsoid by its general convex algorithm, a sphere in closed form: the
    same within 50 um here), and a superellipsoid's mesh and a capsule compile and are
    measured."""
    q = _random_q(hand, 20, seed=3)
    n, names = len(q), _names(hand)
    R = np.tile(np.eye(3), (n, 1, 1))
    p = np.tile(np.asarray(NOMINAL_OBJECT_POSITION, dtype=float), (n, 1))
    hc = hand.collision([0, 1, 2, 3])
    rho = NOMINAL_RADIUS
    ball = hc.least("sphere", (rho,), names, q, R, p)
    for shape, dims in (("ellipsoid", (rho, rho)), ("ellipsoid", (rho, rho, rho))):
        got = hc.least(shape, dims, names, q, R, p)
        assert got.value == pytest.approx(ball.value, abs=5e-5)
        assert set(got.pair) == set(ball.pair) and got.sample == ball.sample
    for shape, dims in (("capsule", (0.012, 0.028)),
                        ("superellipsoid", (0.025, 0.025, 0.025, 0.005))):
        got = hc.least(shape, dims, names, q, R, p)
        assert np.isfinite(got.value) and got.value <= WINDOW
