"""Synthetic scenes with ground truth, for the unit tests and as the notebooks' fallback.

Every random choice comes from the ``rng`` argument (a ``numpy.random.Generator``).
"""
import numpy as np
from numpy.typing import ArrayLike

from .geometry import P_from_KRt, camera_center, project, rotation_from_angle_axis
from .scene import Scene
from .validation import (
    as_calibration,
    as_count,
    as_fraction,
    as_positive,
    as_rng,
    as_rotations,
    as_translations,
    as_vector3,
)

DEFAULT_K = np.array([[1500.0, 0.0, 360.0], [0.0, 1500.0, 288.0], [0.0, 0.0, 1.0]])


def look_at(C, target, up=(0.0, 0.0, 1.0)):
    """Rotation and translation of a camera at ``C`` looking at ``target`` (x right, y down, z forward).

    >>> R, t = look_at(np.array([0., -5., 0.]), np.zeros(3))
    >>> np.allclose(R @ np.zeros(3) + t, [0, 0, 5])
    True
    """
    C, target, up = as_vector3(C, "C"), as_vector3(target, "target"), as_vector3(up, "up")
    z = target - C
    if not np.linalg.norm(z) > 0:
        raise ValueError("target must differ from C (the camera looks from C towards target)")
    if not np.linalg.norm(up) > 0:
        raise ValueError("up must be a non-zero vector")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:                 # looking along `up`: pick another
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ C


def _blob(n, size, rng):
    """Points on a bumpy ellipsoid (an 'object'), with outward normals."""
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    bumps = 1 + 0.15 * np.sin(3 * d[:, 0]) * np.cos(2 * d[:, 1]) + 0.1 * np.sin(4 * d[:, 2])
    axes = np.array([1.0, 0.7, 1.4])
    X = size * d * axes * bumps[:, None]
    normals = d / axes
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return X, normals


def make_scene(n_points: int = 200, n_views: int = 2, layout: str = "general", noise_px: float = 1.0,
               outlier_ratio: float = 0.0, *, rng: np.random.Generator, K: ArrayLike = None,
               image_size: tuple = (720, 576), radius: float = 1.0, object_size: float = None, planar: bool = False,
               min_views: int = 2, track_noise_px: float = None, track_outlier_ratio: float = 0.0) -> Scene:
    """A scene with ground truth: cameras, points, noise-free and noisy projections.

    Parameters
    ----------
    n_points, n_views : int
    layout : {'general', 'turntable', 'forward'}
        ``'general'``: cameras at random places around a point cloud, all looking at it (every point
        seen by every view). ``'turntable'``: cameras on a circle of ``radius`` in the z = 0 plane
        around a bumpy object; a point is seen where its surface faces the camera (like the dinosaur).
        ``'forward'``: the cameras move mostly along their optical axis (the epipole is in the image).
    noise_px : float
        Standard deviation of the Gaussian noise added to each pixel coordinate of ``x_meas``.
    outlier_ratio : float
        Fraction of the visible measurements replaced by uniform random pixels (marked in ``outliers``).
    rng : numpy.random.Generator
        Required: the source of every random choice.
    K : (3, 3) array_like, optional
        Calibration shared by all views (default: f = 1500 px, principal point at the centre).
    planar : bool
        Put all points on one plane (a degenerate scene for the 8-point algorithm and for calibration).
    min_views : int
        Turntable only: drop points seen by fewer views.
    track_noise_px, track_outlier_ratio : float, optional
        When ``track_noise_px`` is given, ``tracks`` is a second, independent measurement of the same
        points with this noise and outlier ratio (a stand-in for the dinosaur's real tracks, which are
        more precise than ``x_meas`` but have outliers); otherwise ``tracks`` is ``x_meas``.

    Returns
    -------
    Scene
        ``source='synthetic'``.

    Raises
    ------
    ValueError
        No ``rng``; a negative noise, a ratio outside [0, 1), a singular K, an unknown layout, ``min_views``
        outside 2..n_views, or a scene in which no point is seen by ``min_views`` views.

    >>> s = make_scene(50, 3, rng=np.random.default_rng(0))
    >>> s.R.shape, s.X.shape, s.x_meas.shape
    ((3, 3, 3), (50, 3), (3, 50, 2))
    """
    as_rng(rng)
    n_points, n_views = as_count(n_points, "n_points", 1), as_count(n_views, "n_views", 2)
    noise_px = as_positive(noise_px, "noise_px", allow_zero=True)
    outlier_ratio = as_fraction(outlier_ratio, "outlier_ratio")
    track_outlier_ratio = as_fraction(track_outlier_ratio, "track_outlier_ratio")
    if track_noise_px is not None:
        track_noise_px = as_positive(track_noise_px, "track_noise_px", allow_zero=True)
    min_views = as_count(min_views, "min_views", 2)
    if min_views > n_views:
        raise ValueError(f"min_views must be at most n_views = {n_views}; got {min_views}")
    radius = as_positive(radius, "radius")
    if object_size is not None:
        object_size = as_positive(object_size, "object_size")
    K = DEFAULT_K.copy() if K is None else as_calibration(K, "K")
    if np.shape(image_size) != (2,) or not all(as_positive(v, "image_size") for v in image_size):
        raise ValueError(f"image_size must be (width, height), two positive numbers; got {image_size!r}")
    w, h = image_size
    if object_size is None:
        object_size = 0.12 * radius if layout == "turntable" else 0.3 * radius

    if layout == "turntable":
        X, normals = _blob(n_points, object_size, rng)
        angles = 2 * np.pi * np.arange(n_views) / n_views
        centres = radius * np.stack([np.cos(angles), np.sin(angles), 0.05 * np.ones(n_views)], axis=1)
        poses = [look_at(C, np.zeros(3)) for C in centres]
    elif layout in ("general", "forward"):
        X = rng.uniform(-object_size, object_size, size=(n_points, 3))
        normals = None
        if layout == "general":
            d = rng.normal(size=(n_views, 3))
            d[:, 2] = -np.abs(d[:, 2]) - 0.5      # all on one side
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            centres = radius * d * 2.5
            targets = rng.normal(scale=0.05 * radius, size=(n_views, 3))
        else:
            centres = np.stack([rng.normal(scale=0.05 * radius, size=n_views),
                                rng.normal(scale=0.05 * radius, size=n_views),
                                -2.5 * radius + 0.5 * radius * np.arange(n_views) / max(n_views - 1, 1)], axis=1)
            targets = centres + np.array([0.0, 0.0, 1.0]) + rng.normal(scale=0.02, size=(n_views, 3))
        poses = [look_at(C, T, up=(0.0, -1.0, 0.0)) for C, T in zip(centres, targets)]
    else:
        raise ValueError(f"layout must be 'general', 'turntable' or 'forward'; got {layout!r}")
    if planar:
        X[:, 2] = 0.0 if layout != "turntable" else X[:, 2].mean()

    R = np.stack([p[0] for p in poses])
    t = np.stack([p[1] for p in poses])
    x_true = np.stack([project(P_from_KRt(K, Ri, ti), X) for Ri, ti in zip(R, t)])
    depth = np.einsum("vj,nj->vn", R[:, 2], X) + t[:, 2:3]
    inside = (x_true[..., 0] >= 0) & (x_true[..., 0] < w) & (x_true[..., 1] >= 0) & (x_true[..., 1] < h)
    seen = inside & (depth > 0)
    if normals is not None:
        C = camera_center(R, t)
        to_cam = C[:, None, :] - X[None]
        facing = np.einsum("vnj,nj->vn", to_cam, normals) / np.linalg.norm(to_cam, axis=-1)
        seen &= facing > 0.25
        keep = seen.sum(0) >= min_views
        X, x_true, seen = X[keep], x_true[:, keep], seen[:, keep]
        if not keep.any():
            raise ValueError(f"no point of the turntable object is seen by min_views = {min_views} views: lower "
                             "min_views or add views")
    x_true[~seen] = np.nan
    x_meas, outliers = _measure(x_true, seen, noise_px, outlier_ratio, (w, h), rng)
    tracks = x_meas
    if track_noise_px is not None:
        tracks, _ = _measure(x_true, seen, track_noise_px, track_outlier_ratio, (w, h), rng)
    return Scene(name=f"synthetic-{layout}", K=K, R=R, t=t, X=X, x_true=x_true, x_meas=x_meas,
                 image_size=(w, h), source="synthetic", noise_px=noise_px, outliers=outliers, tracks=tracks,
                 tracks_noise_px=noise_px if track_noise_px is None else track_noise_px)


def _measure(x_true, seen, noise_px, outlier_ratio, image_size, rng):
    """Noisy copy of ``x_true`` with a fraction of the seen entries replaced by uniform outliers."""
    x = x_true + rng.normal(scale=noise_px, size=x_true.shape) if noise_px > 0 else x_true.copy()
    outliers = np.zeros(seen.shape, bool)
    if outlier_ratio > 0:
        vi, pi = np.nonzero(seen)
        pick = rng.random(vi.size) < outlier_ratio
        outliers[vi[pick], pi[pick]] = True
        x[vi[pick], pi[pick]] = rng.uniform([0, 0], image_size, size=(pick.sum(), 2))
    return x, outliers


def perturb_cameras(R: ArrayLike, t: ArrayLike, *, rng: np.random.Generator, rot_deg: float = 1.0,
                    rel_shift: float = 0.02) -> tuple:
    """Cameras moved off their poses: a starting point for bundle adjustment with known truth.

    Each camera is rotated by a random small rotation of RMS angle ``rot_deg`` degrees and its centre moved by
    a random vector of RMS length ``rel_shift`` times the mean distance of the centres from their centroid.

    Parameters
    ----------
    R : (V, 3, 3) array_like
    t : (V, 3) array_like
    rng : numpy.random.Generator
    rot_deg, rel_shift : float

    Returns
    -------
    R0 : (V, 3, 3) ndarray
    t0 : (V, 3) ndarray

    >>> R0, t0 = perturb_cameras(np.stack([np.eye(3)] * 3), np.eye(3), rng=np.random.default_rng(0))
    >>> R0.shape, t0.shape
    ((3, 3, 3), (3, 3))
    """
    as_rng(rng)
    R = as_rotations(R, "R")
    t = as_translations(t, "t", n=len(R), like_name="R")
    rot_deg = as_positive(rot_deg, "rot_deg", allow_zero=True)
    rel_shift = as_positive(rel_shift, "rel_shift", allow_zero=True)
    C = camera_center(R, t)
    scale = np.linalg.norm(C - C.mean(0), axis=1).mean()
    R0 = rotation_from_angle_axis(rng.normal(size=(len(R), 3)) * np.radians(rot_deg) / np.sqrt(3)) @ R
    C0 = C + rng.normal(size=C.shape) * rel_shift * scale / np.sqrt(3)
    return R0, -np.einsum("vij,vj->vi", R0, C0)
