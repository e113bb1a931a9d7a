"""The gauge: reprojection errors do not change when the whole reconstruction (cameras and points) is moved by a
similarity (rotation, translation, scale: 7 degrees of freedom).

The cost therefore has a 7-dimensional valley of equal minima, ``JᵀJ`` is singular, and "the" solution is only
defined once that freedom is fixed (Triggs et al. 2000, Sec. 9). This module holds the two sides of it:

- fixing it in a solution: ``'first-camera-and-scale'`` holds the pose of a first (anchor) camera and the
  distance between the first two camera centres (:func:`gauge_plan`, :func:`apply_gauge`, used by
  :func:`labutils.bundle.bundle_adjust`);
- its directions in parameter space: :func:`gauge_basis`, the 7 infinitesimal similarities that the reprojection
  Jacobian maps to zero (used by :mod:`labutils.bundle.uncertainty`).
"""
import numpy as np
from numpy.typing import ArrayLike

from ..core.geometry import angle_axis_from_rotation, camera_center, left_jacobian_so3, rotation_from_angle_axis, skew
from ..core.validation import as_points, as_rotations, as_translations

GAUGES = ("first-camera-and-scale", None)


def _centres(cp):
    R = rotation_from_angle_axis(cp[:, :3])
    return camera_center(R, cp[:, 3:6]), R


def gauge_plan(cp, fixed_cameras, fixed_points, gauge):
    """Freeze the user's fixed cameras; choose the anchor and scale cameras of the gauge.

    Returns ``free_cam (V, k)`` (False for the held pose parameters) and the gauge ``info`` dict
    (empty when no gauge is imposed).
    """
    V, k = cp.shape
    free_cam = np.ones((V, k), bool)
    fc = np.unique(np.asarray(fixed_cameras if fixed_cameras is not None else [], dtype=np.int64).ravel())
    if fc.size and (fc.min() < 0 or fc.max() >= V):
        raise ValueError(f"fixed_cameras must index existing cameras 0..{V - 1}; got {fc.tolist()}")
    free_cam[fc, :6] = False
    if gauge is not None and gauge not in GAUGES:
        raise ValueError(f"gauge must be 'first-camera-and-scale' or None; got {gauge!r}")
    if gauge is None or fc.size >= 2 or (fixed_points is not None and fixed_points.sum() >= 3):
        return free_cam, {}                                     # nothing asked, or the fixed things hold it
    anchor = int(fc[0]) if fc.size else 0
    C, R = _centres(cp)
    dist = np.linalg.norm(C - C[anchor], axis=1)
    others = np.flatnonzero((np.arange(V) != anchor) & (dist > 1e-9 * max(dist.max(), 1e-300)))
    if not others.size:
        raise ValueError("gauge='first-camera-and-scale' needs a second camera with a different centre "
                         "(all camera centres coincide, or there is only one camera)")
    b = int(others[0])
    return free_cam, dict(anchor=anchor, scale_camera=b, baseline=float(dist[b]), R_anchor=R[anchor],
                          C_anchor=C[anchor])


def apply_gauge(cp, X, free_cam, info):
    """Move the solution by the similarity that restores the gauge; return it and the gauge's columns.

    The similarity ``X' = s Q X + c`` puts the anchor camera back at its starting pose (``Q``, ``c``) and
    makes the distance from it to the scale camera its starting length (``s``); it changes no residual.
    The columns returned as held (for ``BundleResult.free``) are the anchor's six pose parameters and the
    coordinate ``j`` of the scale camera's translation that the scale moves most (the largest coordinate
    of ``-R_b (C_b - C_a)``): removing them from ``J`` removes the 7-dimensional null space.
    """
    free_cam = free_cam.copy()
    if not info:
        return cp, X, free_cam
    a, b = info["anchor"], info["scale_camera"]
    C, R = _centres(cp)
    Q = info["R_anchor"].T @ R[a]                                # R_a Qᵀ = R_anchor
    s = info["baseline"] / np.linalg.norm(C[b] - C[a])
    c = info["C_anchor"] - s * Q @ C[a]
    R_new = R @ Q.T
    C_new = s * C @ Q.T + c
    cp = cp.copy()
    cp[:, :3] = angle_axis_from_rotation(R_new)
    cp[:, 3:6] = -np.einsum("vij,vj->vi", R_new, C_new)
    free_cam[a, :6] = False
    j = int(np.argmax(np.abs(R_new[b] @ (C_new[b] - C_new[a]))))
    free_cam[b, 3 + j] = False
    return cp, s * X @ Q.T + c, free_cam


def gauge_basis(R: ArrayLike, t: ArrayLike, X: ArrayLike) -> np.ndarray:
    """The 7 infinitesimal similarities of a reconstruction, in bundle-adjustment parameters.

    The parameters are those of :mod:`labutils.bundle.adjust`: per camera the angle-axis vector ``ω`` and
    ``t`` (6 numbers), then the points (3 numbers each). A similarity ``X' = (1 + λ) exp([q]×) X + u``
    moves them by ``δX = q × X + λ X + u``, ``δω = -J_l(ω)⁻¹ R q``, ``δt = λ t - R u`` and leaves every
    projection unchanged, so the reprojection Jacobian maps each column to zero (Triggs et al. Sec. 9).

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    X : (M, 3) array_like

    Returns
    -------
    N : (6 V + 3 M, 7) ndarray
        Columns: rotation about x, y, z; translation along x, y, z; scale.

    >>> from labutils.core.synthetic import make_scene
    >>> s = make_scene(20, 4, rng=np.random.default_rng(0))
    >>> gauge_basis(s.R, s.t, s.X).shape
    (84, 7)
    """
    R = as_rotations(R, "R")
    t = as_translations(t, "t", n=len(R), like_name="R")
    X = as_points(X, "X", dim=3)
    V, M = len(R), len(X)
    Jl = left_jacobian_so3(angle_axis_from_rotation(R))
    N = np.zeros((6 * V + 3 * M, 7))
    cam = N[:6 * V].reshape(V, 6, 7)
    pts = N[6 * V:].reshape(M, 3, 7)
    cam[:, :3, :3] = -np.linalg.solve(Jl, R)               # δω for the rotation q
    cam[:, 3:, 3:6] = -R                                   # δt for the translation u
    cam[:, 3:, 6] = t                                      # δt for the scale λ
    pts[:, :, :3] = -np.stack([skew(x) for x in X]) if M else 0.0     # q × X = -[X]× q
    pts[:, :, 3:6] = np.eye(3)
    pts[:, :, 6] = X
    return N
