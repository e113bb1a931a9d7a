"""A synthetic object for space carving, with ground truth: a "snowman" of spheres, cameras around it, images.

The truth is analytic: a pixel's ray hits a sphere or not, so the exact silhouettes, the object's volume, and
whether a point lies in the exact visual hull (its ray hits the object in every view) are known. Used by the unit
tests and as notebook 11's fallback when the real data is missing.

Every random choice comes from the ``rng`` argument (a ``numpy.random.Generator``).
"""
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ...core.scene import CameraRig
from ...core.synthetic import look_at

__all__ = ["CarvingScene", "make_snowman", "rays_hit_spheres"]

SNOWMAN = np.array([[0.0, 0.0, 0.0, 0.30], [0.0, 0.0, 0.40, 0.20], [0.0, 0.0, 0.68, 0.12],
                    [0.21, 0.0, 0.42, 0.05], [-0.21, 0.0, 0.42, 0.05]])
"""Spheres (x, y, z, radius): body, chest, head, two hands."""


def _spheres_box(spheres):
    """(2, 3): the tight axis-aligned box around spheres given as rows (x, y, z, radius)."""
    s = np.asarray(spheres, float)
    return np.array([(s[:, :3] - s[:, 3:]).min(axis=0), (s[:, :3] + s[:, 3:]).max(axis=0)])


@dataclass
class CarvingScene(CameraRig):
    """Cameras, images and exact silhouettes of a union of spheres.

    Attributes
    ----------
    K : (V, 3, 3) ndarray
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        ``x_cam = R @ X + t``.
    images : list of (H, W, 3) uint8 RGB
        Orange spheres, shaded, on a blue background with a gradient, plus pixel noise.
    masks : list of (H, W) bool
        The exact silhouettes (pixel centres whose ray hits a sphere).
    spheres : (M, 4) ndarray
        Centre and radius of each sphere.
    name, source : str
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    images: list = field(repr=False)
    masks: list = field(repr=False)
    spheres: np.ndarray = field(default_factory=lambda: SNOWMAN.copy())
    name: str = "snowman"
    source: str = "synthetic"

    @property
    def box(self):
        """(2, 3): the tight box around the spheres."""
        return _spheres_box(self.spheres)

    def inside_object(self, X: ArrayLike) -> np.ndarray:
        """(N,) bool: which points lie inside a sphere."""
        X = np.asarray(X, float)
        d = np.linalg.norm(X[:, None, :] - self.spheres[None, :, :3], axis=2)
        return np.any(d < self.spheres[None, :, 3], axis=1)

    def inside_hull(self, X: ArrayLike) -> np.ndarray:
        """(N,) bool: which points lie in the exact visual hull (their ray hits the object in every view)."""
        X = np.asarray(X, float)
        out = np.ones(len(X), bool)
        for C in self.C:
            out &= rays_hit_spheres(C, X - C, self.spheres)
        return out


def rays_hit_spheres(C: ArrayLike, d: ArrayLike, spheres: ArrayLike) -> np.ndarray:
    """Which rays ``C + s d`` (s > 0) hit at least one sphere.

    Parameters
    ----------
    C : (3,) ray origin
    d : (N, 3) directions (any length)
    spheres : (M, 4) centre and radius

    Returns
    -------
    (N,) bool

    >>> rays_hit_spheres(np.zeros(3), np.array([[0., 0, 1], [0, 1, 0], [0, 0, -1]]), np.array([[0, 0, 5, 1.]])).tolist()
    [True, False, False]
    """
    d = np.asarray(d, float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    hit = np.zeros(len(d), bool)
    for S, r in zip(spheres[:, :3], spheres[:, 3]):
        v = S - C
        along = d @ v                                     # distance along the ray to the closest approach
        dist2 = v @ v - along ** 2
        hit |= (dist2 < r * r) & (along > 0)
    return hit


def make_snowman(n_views: int = 24, *, rng: np.random.Generator, image_size: tuple[int, int] = (320, 240),
                 f: float = 420.0, distance: float = 3.0, elevations: Sequence[float] = (15.0, 45.0),
                 noise: float = 2.0, spheres: ArrayLike | None = None) -> CarvingScene:
    """Cameras on rings around a snowman of spheres, its images and its exact silhouettes.

    Parameters
    ----------
    n_views : int
        Views, split between the ``elevations`` (degrees above the ground plane z = 0).
    rng : numpy.random.Generator
        Pixel noise (and nothing else: the cameras are on regular rings).
    image_size : (width, height)
    f : float
        Focal length, pixels (principal point at the image centre).
    distance : float
        Cameras' distance from the snowman's centre (0, 0, 0.3).
    noise : float
        Standard deviation of the pixel noise, grey levels.
    spheres : (M, 4) array_like, optional
        Centre and radius of each sphere (default: :data:`SNOWMAN`).

    Returns
    -------
    CarvingScene

    Examples
    --------
    >>> s = make_snowman(6, rng=np.random.default_rng(0), image_size=(64, 48), f=84.0)
    >>> s.P.shape, s.images[0].shape, s.images[0].dtype, bool(s.masks[0].any())
    ((6, 3, 4), (48, 64, 3), dtype('uint8'), True)
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    if n_views < 2:
        raise ValueError(f"n_views must be >= 2; got {n_views}")
    spheres = SNOWMAN.copy() if spheres is None else np.asarray(spheres, float).reshape(-1, 4)
    w, h = (int(v) for v in image_size)
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    target = np.array([0.0, 0.0, 0.3])
    elev = np.deg2rad(np.asarray(elevations, float))
    Rs, ts, images, masks = [], [], [], []
    yy, xx = np.mgrid[0:h, 0:w]
    pix_h = np.stack([xx.ravel(), yy.ravel(), np.ones(w * h)], axis=1).astype(float)
    light = np.array([0.4, -0.3, 0.85])
    light /= np.linalg.norm(light)
    for v in range(n_views):
        e = elev[v % len(elev)]
        a = 2 * np.pi * v / n_views
        C = target + distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        R, t = look_at(C, target)
        d = pix_h @ np.linalg.inv(K).T @ R                 # ray directions in the world: R^T K^-1 x
        hit, shade = _shade(C, d, spheres, light)
        img = np.empty((h * w, 3))
        grad = (yy.ravel() / h)[:, None]
        img[:] = np.array([60.0, 75.0, 170.0]) * (0.8 + 0.4 * grad)          # blue background, brighter below
        img[hit] = np.array([235.0, 130.0, 40.0]) * shade[hit, None]         # orange, shaded
        img += rng.normal(0.0, noise, img.shape)
        images.append(np.clip(np.round(img), 0, 255).astype(np.uint8).reshape(h, w, 3))
        masks.append(hit.reshape(h, w))
        Rs.append(R)
        ts.append(t)
    return CarvingScene(np.repeat(K[None], n_views, axis=0), np.array(Rs), np.array(ts), images, masks, spheres)


def _shade(C, d, spheres, light):
    """Nearest sphere hit by each ray and its Lambertian shade (0.35 ambient)."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    best = np.full(len(d), np.inf)
    normal = np.zeros_like(d)
    for S, r in zip(spheres[:, :3], spheres[:, 3]):
        v = S - C
        along = d @ v
        disc = along ** 2 - (v @ v - r * r)
        ok = disc > 0
        s = np.where(ok, along - np.sqrt(np.maximum(disc, 0)), np.inf)
        ok &= (s > 0) & (s < best)
        best = np.where(ok, s, best)
        normal[ok] = (C + s[ok, None] * d[ok] - S) / r
    hit = np.isfinite(best)
    return hit, 0.35 + 0.65 * np.clip(normal @ light, 0, 1)
