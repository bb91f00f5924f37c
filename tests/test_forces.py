"""Forces in the plan (issue 15): the request's load and grip, validated field by field;
on a plan, every collocation point's forces balance the object's weight to round-off,
lie inside their friction cones with the margin, push at least the minimum, and the joint
torques are J^T f by Pinocchio's own Jacobian."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from test_manipulation import two_fingers

from ocp.spec.problem import ForceSpec, ObjectSpec, ProblemError

LOAD = ForceSpec(mass=0.05, min_normal_force=1.0, torsional_friction=0.005)


@pytest.mark.parametrize(("patch", "field", "words"), [
    ({"mass": -0.1}, "forces.mass", "(0, 100] kg"),
    ({"mass": math.nan}, "forces.mass", "(0, 100] kg"),
    ({"gravity": (0.0, math.inf, -9.81)}, "forces.gravity", "finite"),
    ({"gravity": (0.0, -9.81)}, "forces.gravity", "3 finite"),
    ({"inertia": (1e-5, 0.0, 1e-5)}, "forces.inertia", "principal moments"),
    ({"min_normal_force": 0.0}, "forces.min_normal_force", "(0, 1000] N"),
    ({"torsional_friction": -1e-3}, "forces.torsional_friction", "[0, 0.1] m"),
    ({"cone_margin": 1.0}, "forces.cone_margin", "atan(mu)"),
])
def test_bad_forces_name_the_field(patch: dict[str, Any], field: str, words: str) -> None:
    problem = two_fingers(n=10, forces=replace(LOAD, **patch))
    with pytest.raises(ProblemError) as exc:
        problem.validate()
    errs = dict(exc.value.errors)
    assert field in errs and words in errs[field], errs


def test_the_default_inertia_is_the_solid_bodys() -> None:
    ball = ObjectSpec("sphere", (0.025,))
    assert np.allclose(ForceSpec(0.05).principal_inertia(ball), [0.4 * 0.05 * 0.025**2] * 3)
    egg = ObjectSpec("ellipsoid", (0.02, 0.03))
    Ix, Iy, Iz = ForceSpec(2.0).principal_inertia(egg)
    assert np.isclose(Ix, 2.0 * (0.02**2 + 0.03**2) / 5) and Ix == Iy
    assert np.isclose(Iz, 2 * 2.0 * 0.02**2 / 5)
    assert ForceSpec(1.0, inertia=(1.0, 2.0, 3.0)).principal_inertia(egg) == (1.0, 2.0, 3.0)
