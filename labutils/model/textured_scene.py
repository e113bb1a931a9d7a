"""A synthetic textured object with exact truth: a snowman of spheres painted with stripes, its images by ray casting,
points on its surface with their normals, colours and visibility.

What notebook 10 and its tests need to judge point clouds, normals and textures: the colour a camera sees at a
surface point is known exactly (a striped albedo times a Lambertian shade from a light fixed in the world, so every
view sees a point in the same colour), a point's outward normal is known, and which views see it (in the image,
facing the camera, and the first thing its ray hits) is computed exactly. Every random choice comes from ``rng``.
"""
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..core.scene import CameraRig
from ..core.synthetic import look_at
from ..core.validation import as_count, as_image_size, as_points, as_positive, as_rng
from .carving.synthetic import SNOWMAN

__all__ = ["TexturedScene", "make_textured_scene"]

_LIGHT = np.array([0.4, -0.3, 0.85]) / np.linalg.norm([0.4, -0.3, 0.85])


@dataclass
class TexturedScene(CameraRig):
    """Cameras around a striped snowman of spheres, and its images.

    Attributes
    ----------
    K : (V, 3, 3) ndarray
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        ``x_cam = R @ X + t``.
    images : list of (H, W, 3) uint8 RGB
    spheres : (M, 4) ndarray
        Centre and radius of each sphere.
    image_size : (width, height)
    noise : float
        Standard deviation of the pixel noise added to the images (grey levels).
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    images: list = field(repr=False)
    spheres: np.ndarray = field(default_factory=lambda: SNOWMAN.copy())
    image_size: tuple = (320, 240)
    noise: float = 0.0
    name: str = "textured snowman"
    source: str = "synthetic"

    def image(self, i):
        """View ``i`` (like ``Scene.image``)."""
        return self.images[i]

    def colour(self, X: ArrayLike, normals: ArrayLike) -> np.ndarray:
        """(N, 3) float: the colour every camera sees at surface points ``X`` with outward ``normals`` (noise-free)."""
        X = as_points(X, "X", dim=3)
        normals = as_points(normals, "normals", dim=3, like=(X, "X"))
        return _albedo(X) * (0.35 + 0.65 * np.clip(normals @ _LIGHT, 0, 1))[:, None]

    def surface_points(self, n: int, *, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``n`` points spread uniformly (by area) over the outer surface of the union of spheres, and their normals.

        Returns
        -------
        X : (n, 3) ndarray
        normals : (n, 3) ndarray
            Outward unit normals.
        """
        as_rng(rng)
        n = as_count(n, "n", 1)
        area = 4 * np.pi * self.spheres[:, 3] ** 2
        X, N = np.zeros((0, 3)), np.zeros((0, 3))
        while len(X) < n:
            k = rng.choice(len(self.spheres), size=2 * n, p=area / area.sum())
            d = rng.normal(size=(2 * n, 3))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            P = self.spheres[k, :3] + self.spheres[k, 3:] * d
            inner = np.linalg.norm(P[:, None] - self.spheres[None, :, :3], axis=2) < self.spheres[None, :, 3] - 1e-9
            out = ~inner.any(axis=1)                      # not inside another sphere: on the outer surface
            X, N = np.vstack([X, P[out]]), np.vstack([N, d[out]])
        return X[:n], N[:n]

    def visibility(self, X: ArrayLike, normals: ArrayLike) -> np.ndarray:
        """(V, N) bool: which views see each surface point — in the image, facing the camera, the ray's first hit."""
        X = as_points(X, "X", dim=3)
        normals = as_points(normals, "normals", dim=3, like=(X, "X"))
        w, h = self.image_size
        vis = np.zeros((self.n_views, len(X)), bool)
        for v, (K, R, t, C) in enumerate(zip(self.K, self.R, self.t, self.C)):
            c = X @ R.T + t
            x = (c @ K.T)[:, :2] / c[:, 2:]
            d = X - C
            dist = np.linalg.norm(d, axis=1)
            first = _first_hit(C, d, self.spheres)
            vis[v] = ((c[:, 2] > 0) & (x[:, 0] >= 0) & (x[:, 0] <= w - 1) & (x[:, 1] >= 0) & (x[:, 1] <= h - 1)
                      & (np.einsum("ij,ij->i", normals, -d) > 0) & (first >= dist - 1e-6 * dist))
        return vis

    def project(self, X: ArrayLike, visible: ArrayLike) -> np.ndarray:
        """(V, N, 2) pixels of ``X`` in every view, NaN where ``visible`` is False (a track array)."""
        X = as_points(X, "X", dim=3)
        c = np.einsum("vij,nj->vni", self.R, X) + self.t[:, None]
        q = np.einsum("vij,vnj->vni", self.K, c)
        x = q[..., :2] / q[..., 2:]
        return np.where(np.asarray(visible, bool)[..., None], x, np.nan)


    def make_tracks(self, n: int, *, noise_px: float, rng: np.random.Generator, min_views: int = 2) -> tuple:
        """Surface points seen by at least ``min_views`` views, and their tracks with Gaussian pixel noise.

        Returns
        -------
        X : (M, 3) ndarray
            The points (M <= n: those seen by too few views are dropped).
        normals : (M, 3) ndarray
        tracks : (V, M, 2) ndarray
            Noisy pixels, NaN where a view does not see a point.
        """
        noise_px = as_positive(noise_px, "noise_px", allow_zero=True)
        X, normals = self.surface_points(n, rng=rng)
        vis = self.visibility(X, normals)
        keep = vis.sum(axis=0) >= as_count(min_views, "min_views", 1)
        X, normals, vis = X[keep], normals[keep], vis[:, keep]
        return X, normals, self.project(X, vis) + rng.normal(scale=noise_px, size=(self.n_views, len(X), 2))


def _albedo(X):
    """Orange and yellow stripes around the vertical axis, with a green band: a texture with edges."""
    s = 0.5 + 0.5 * np.sin(24.0 * np.arctan2(X[:, 1], X[:, 0]) + 9.0 * X[:, 2])
    base = np.array([225.0, 110.0, 35.0]) * (1 - s)[:, None] + np.array([245.0, 215.0, 60.0]) * s[:, None]
    band = np.exp(-((X[:, 2] - 0.25) / 0.06) ** 2)[:, None]
    return base * (1 - band) + np.array([60.0, 150.0, 70.0]) * band


def _first_hit(C, d, spheres):
    """(N,) distance along each ray ``C + s d / ‖d‖`` to the first sphere it hits (inf: none)."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    best = np.full(len(d), np.inf)
    for S, r in zip(spheres[:, :3], spheres[:, 3]):
        v = S - C
        along = d @ v
        disc = along ** 2 - (v @ v - r * r)
        s = np.where(disc > 0, along - np.sqrt(np.maximum(disc, 0)), np.inf)
        best = np.where((s > 0) & (s < best), s, best)
    return best


def make_textured_scene(n_views: int = 24, *, rng: np.random.Generator, image_size: tuple[int, int] = (320, 240),
                        f: float = 420.0, distance: float = 3.0, elevations: Sequence[float] = (15.0, 45.0),
                        noise: float = 2.0, spheres: ArrayLike | None = None) -> TexturedScene:
    """Cameras on rings around a striped snowman, and its images, ray cast exactly (then pixel noise).

    Parameters
    ----------
    n_views : int
        Views, split between the ``elevations`` (degrees above the ground plane), all looking at (0, 0, 0.3).
    rng : numpy.random.Generator
        The pixel noise.
    image_size : (width, height)
    f : float
        Focal length, pixels.
    distance : float
    noise : float
        Standard deviation of the pixel noise, grey levels.
    spheres : (M, 4) array_like, optional
        Centre and radius of each sphere (default: the snowman of :mod:`labutils.model.carving.synthetic`).

    Returns
    -------
    TexturedScene

    Examples
    --------
    >>> s = make_textured_scene(4, rng=np.random.default_rng(0), image_size=(64, 48), f=84.0)
    >>> X, n = s.surface_points(100, rng=np.random.default_rng(1))
    >>> s.images[0].shape, X.shape, bool(s.visibility(X, n).any(axis=0).mean() > 0.5)
    ((48, 64, 3), (100, 3), True)
    """
    as_rng(rng)
    n_views = as_count(n_views, "n_views", 2)
    noise = as_positive(noise, "noise", allow_zero=True)
    f = as_positive(f, "f")
    spheres = SNOWMAN.copy() if spheres is None else np.asarray(spheres, float).reshape(-1, 4)
    w, h = as_image_size(image_size, minimum=2)
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    target = np.array([0.0, 0.0, 0.3])
    elev = np.deg2rad(np.asarray(elevations, float))
    yy, xx = np.mgrid[0:h, 0:w]
    pix_h = np.stack([xx.ravel(), yy.ravel(), np.ones(w * h)], axis=1).astype(float)
    Rs, ts, images = [], [], []
    for v in range(n_views):
        e = elev[v % len(elev)]
        a = 2 * np.pi * v / n_views
        C = target + distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        R, t = look_at(C, target)
        d = pix_h @ np.linalg.inv(K).T @ R
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        s = _first_hit(C, d, spheres)
        hit = np.isfinite(s)
        img = np.empty((h * w, 3))
        img[:] = np.array([60.0, 75.0, 170.0]) * (0.8 + 0.4 * (yy.ravel() / h))[:, None]
        P = C + s[hit, None] * d[hit]
        k = np.argmin(np.abs(np.linalg.norm(P[:, None] - spheres[None, :, :3], axis=2) - spheres[None, :, 3]), axis=1)
        normals = (P - spheres[k, :3]) / spheres[k, 3:]
        img[hit] = _albedo(P) * (0.35 + 0.65 * np.clip(normals @ _LIGHT, 0, 1))[:, None]
        img += rng.normal(0.0, noise, img.shape) if noise > 0 else 0.0
        images.append(np.clip(np.round(img), 0, 255).astype(np.uint8).reshape(h, w, 3))
        Rs.append(R)
        ts.append(t)
    return TexturedScene(np.repeat(K[None], n_views, axis=0), np.array(Rs), np.array(ts), images, spheres, (w, h),
                         noise)
