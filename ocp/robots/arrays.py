"""Validated, read-only arrays of the robot models (fingers, hands, inverse kinematics)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def readonly(a: ArrayLike) -> FloatArray:
    """A float copy of ``a`` that cannot be written (a model's data is shared)."""
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


def rotation(R: ArrayLike, what: str) -> FloatArray:
    """``R`` as a 3x3 rotation matrix; ValueError naming ``what`` when it is not one."""
    Ra = np.asarray(R, dtype=float)
    if Ra.shape != (3, 3) or not np.all(np.isfinite(Ra)):
        raise ValueError(f"{what} must be a finite 3x3 matrix, got shape {Ra.shape}")
    if not np.allclose(Ra.T @ Ra, np.eye(3), atol=1e-9) or np.linalg.det(Ra) < 0.0:
        raise ValueError(f"{what} must be a rotation matrix (orthonormal, det +1)")
    return Ra


def vector3(p: ArrayLike, what: str) -> FloatArray:
    """``p`` as 3 finite numbers; ValueError naming ``what`` when it is not."""
    pa = np.asarray(p, dtype=float).reshape(-1)
    if pa.shape != (3,) or not np.all(np.isfinite(pa)):
        raise ValueError(f"{what} must be 3 finite numbers [m]")
    return pa
