"""The point of a closed convex surface nearest to a point (:func:`nearest_surface_point`):
on the surface's own chart, with the Surface API alone (its geometry and support points).
Round fingertips placed on any object from joint angles (:mod:`ocp.spec.grasp`) and the
first-grasp search (:mod:`ocp.robots.first_grasp`) use it."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["nearest_surface_point"]

FloatArray = NDArray[np.float64]

#: Unit directions (a cube's faces, edges and corners) whose support points seed
#: :func:`nearest_surface_point`.
_SEED_DIRECTIONS = np.array([d for d in np.ndindex(3, 3, 3) if d != (1, 1, 1)],
                            dtype=float) - 1.0
_SEED_DIRECTIONS /= np.linalg.norm(_SEED_DIRECTIONS, axis=1, keepdims=True)


def nearest_surface_point(surface: Any, params: ArrayLike, point: ArrayLike,
                          alpha: ArrayLike | None = None) -> tuple[FloatArray, float]:
    """The point of a closed convex ``surface`` nearest to ``point`` (body frame of the
    chart [m]): (its chart coordinates (u, v), the signed distance [m] along its outward
    normal, negative inside). Damped Newton's method on the chart coordinates (the
    tangential part ``[x y]^T (point - f)`` vanishes, its Jacobian ``-(I + t K) M``, t the
    distance), from ``alpha`` or the support point of the direction n, of the point's own
    and :data:`_SEED_DIRECTIONS`, of the largest ``n . point - h(n)`` (h the support
    function: the signed distance is the largest over all n)."""
    c = np.asarray(point, dtype=float)
    prm = np.asarray(params, dtype=float)
    if alpha is None:
        norm = float(np.linalg.norm(c))
        dirs = _SEED_DIRECTIONS if norm == 0.0 else np.vstack([c / norm, _SEED_DIRECTIONS])
        best = dirs[int(np.argmax(dirs @ c - surface.support_heights(dirs, prm)))]
        alpha = surface.inverse(surface.support_point(best, prm), prm)
    a = np.asarray(alpha, dtype=float).reshape(2)
    scale = float(np.max(prm))

    def at(aa: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        p, G, M, K, _ = surface.geometry(aa, prm)
        return (np.asarray(p, dtype=float).ravel(), np.asarray(G, dtype=float),
                np.asarray(M, dtype=float), np.asarray(K, dtype=float))

    p, G, M, K = at(a)
    for _ in range(60):
        e = c - p
        r = G[:, :2].T @ e
        t = float(G[:, 2] @ e)
        if float(np.linalg.norm(r)) <= 1e-14 * scale:
            break
        H = np.eye(2) + t * K
        if np.linalg.eigvalsh(0.5 * (H + H.T))[0] <= 1e-6:  # deep inside: Gauss-Newton
            H = np.eye(2)
        step = np.linalg.lstsq(H @ M, r, rcond=1e-12)[0]  # lstsq: M is singular at a pole
        size = float(np.linalg.norm(M @ step))
        if size > 0.5 * scale:
            step *= 0.5 * scale / size
        d2 = float(e @ e)
        for _ in range(30):
            got = at(a + step)
            if float((c - got[0]) @ (c - got[0])) <= d2 * (1.0 + 1e-12) + 1e-30:
                break
            step *= 0.5
        a = a + step
        p, G, M, K = got
    return a, float(G[:, 2] @ (c - p))
