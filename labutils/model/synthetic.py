"""The synthetic object of the 3D-model notebooks (10–12), with exact truth: a union of spheres, painted, lit, and
seen by cameras on rings around it, ray cast exactly.

One scene, :class:`SphereScene`, and one renderer serve the three uses:

- :func:`make_snowman` (notebook 11, carving): a plain orange snowman on a blue gradient — exact silhouettes,
  volume, and whether a point lies in the exact visual hull (its ray hits the object in every view);
- :func:`make_textured_scene` (notebook 10, points, normals, texture): the snowman painted with stripes — the colour
  every camera sees at a surface point, its outward normal and which views see it;
- :func:`make_textured_spheres` (notebook 12, dense stereo): four spheres with 3-D wave textures on a dark
  background — the true depth of every pixel.

A pixel's ray hits a sphere or not, so masks, depths, colours and visibility are known exactly; then Gaussian pixel
noise. Every random choice comes from ``rng``.
"""
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..core.scene import CameraRig
from ..core.synthetic import look_at
from ..core.validation import as_count, as_image_size, as_points, as_positive, as_rng

__all__ = ["SNOWMAN", "SPHERES", "SphereScene", "make_snowman", "make_textured_scene", "make_textured_spheres",
           "rays_hit_spheres"]

SNOWMAN = np.array([[0.0, 0.0, 0.0, 0.30], [0.0, 0.0, 0.40, 0.20], [0.0, 0.0, 0.68, 0.12],
                    [0.21, 0.0, 0.42, 0.05], [-0.21, 0.0, 0.42, 0.05]])
"""Spheres (x, y, z, radius): body, chest, head, two hands."""

SPHERES = np.array([[0.0, 0.0, 0.0, 0.30], [0.0, 0.0, 0.42, 0.20], [0.22, 0.12, 0.05, 0.12], [-0.2, -0.16, 0.1, 0.1]])
"""Four spheres standing together: the dense-stereo scene."""


@dataclass
class SphereScene(CameraRig):
    """Cameras around a union of spheres, their images, and the exact truth.

    Attributes
    ----------
    K : (V, 3, 3) ndarray
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        ``x_cam = R @ X + t``.
    images : list of (H, W, 3) uint8 RGB
    masks : list of (H, W) bool
        The exact silhouettes (pixel centres whose ray hits a sphere).
    depths : (V, H, W) ndarray
        True depth of each pixel along the camera's z axis, NaN on the background.
    spheres : (M, 4) ndarray
        Centre and radius of each sphere.
    image_size : (width, height)
    noise : float
        Standard deviation of the pixel noise (grey levels).
    albedo : callable
        ``(X (N, 3), sphere (N,)) -> (N, 3)`` RGB, the paint at surface points.
    light : (3,) ndarray
        Unit direction towards the light, fixed in the world (so every view sees a point in the same colour).
    ambient : float
        Shade ``ambient + (1 - ambient) max(0, n · light)``.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    images: list = field(repr=False)
    masks: list = field(repr=False)
    depths: np.ndarray = field(repr=False)
    spheres: np.ndarray = field(default_factory=lambda: SNOWMAN.copy())
    image_size: tuple = (320, 240)
    noise: float = 0.0
    albedo: Callable = field(default=None, repr=False)
    light: np.ndarray = field(default=None, repr=False)
    ambient: float = 0.35
    name: str = "spheres"
    source: str = "synthetic"

    def image(self, i):
        """View ``i`` (like ``Scene.image``)."""
        return self.images[i]

    @property
    def box(self):
        """(2, 3): the tight axis-aligned box around the spheres."""
        s = self.spheres
        return np.array([(s[:, :3] - s[:, 3:]).min(axis=0), (s[:, :3] + s[:, 3:]).max(axis=0)])

    def distance_to_surface(self, X: ArrayLike) -> np.ndarray:
        """(N,) signed distance of points to the union of the spheres (negative inside)."""
        X = as_points(X, "X", dim=3)
        return np.min(np.linalg.norm(X[:, None] - self.spheres[None, :, :3], axis=2) - self.spheres[:, 3], axis=1)

    def inside_object(self, X: ArrayLike) -> np.ndarray:
        """(N,) bool: which points lie inside a sphere."""
        return self.distance_to_surface(X) < 0

    def inside_hull(self, X: ArrayLike) -> np.ndarray:
        """(N,) bool: which points lie in the exact visual hull (their ray hits the object in every view)."""
        X = as_points(X, "X", dim=3)
        out = np.ones(len(X), bool)
        for C in self.C:
            out &= rays_hit_spheres(C, X - C, self.spheres)
        return out

    def colour(self, X: ArrayLike, normals: ArrayLike) -> np.ndarray:
        """(N, 3) float: the colour every camera sees at surface points ``X`` with outward ``normals`` (noise-free)."""
        X = as_points(X, "X", dim=3)
        normals = as_points(normals, "normals", dim=3, like=(X, "X"))
        k = np.argmin(np.abs(np.linalg.norm(X[:, None] - self.spheres[None, :, :3], axis=2) - self.spheres[:, 3]),
                      axis=1)
        return self.albedo(X, k) * self._shade(normals)[:, None]

    def _shade(self, normals):
        return self.ambient + (1 - self.ambient) * np.clip(normals @ self.light, 0, 1)

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

    def visibility(self, X: ArrayLike, normals: ArrayLike = None) -> np.ndarray:
        """(V, N) bool: which views see each surface point — in front and in the image, the first thing its ray hits,
        and (when ``normals`` are given) facing the camera."""
        X = as_points(X, "X", dim=3)
        if normals is not None:
            normals = as_points(normals, "normals", dim=3, like=(X, "X"))
        w, h = self.image_size
        vis = np.zeros((self.n_views, len(X)), bool)
        for v, (K, R, t, C) in enumerate(zip(self.K, self.R, self.t, self.C)):
            c = X @ R.T + t
            with np.errstate(divide="ignore", invalid="ignore"):
                x = (c @ K.T)[:, :2] / c[:, 2:]
            d = X - C
            dist = np.linalg.norm(d, axis=1)
            first, _ = _first_hit(C, d, self.spheres)
            vis[v] = ((c[:, 2] > 0) & (x[:, 0] >= 0) & (x[:, 0] <= w - 1) & (x[:, 1] >= 0) & (x[:, 1] <= h - 1)
                      & (first >= dist - 1e-6 * dist))
            if normals is not None:
                vis[v] &= np.einsum("ij,ij->i", normals, -d) > 0
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
        hit |= (v @ v - along ** 2 < r * r) & (along > 0)
    return hit


def _first_hit(C, d, spheres):
    """Distance along each ray ``C + s d / ‖d‖`` to the first sphere it hits (inf: none), and that sphere (-1)."""
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    best = np.full(len(d), np.inf)
    which = np.full(len(d), -1)
    for k, (S, r) in enumerate(zip(spheres[:, :3], spheres[:, 3])):
        v = S - C
        along = d @ v
        disc = along ** 2 - (v @ v - r * r)
        s = np.where(disc > 0, along - np.sqrt(np.maximum(disc, 0)), np.inf)
        nearer = (s > 0) & (s < best)
        best, which = np.where(nearer, s, best), np.where(nearer, k, which)
    return best, which


def _ring(n_views, target, distance, elevations_deg):
    """Cameras' (R, t) on rings around ``target``: view v at elevation ``elevations[v % len]`` and azimuth 2πv/n."""
    elev = np.deg2rad(np.asarray(elevations_deg, float))
    poses = []
    for v in range(n_views):
        e, a = elev[v % len(elev)], 2 * np.pi * v / n_views
        poses.append(look_at(target + distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]),
                             target))
    return np.array([R for R, _ in poses]), np.array([t for _, t in poses])


def _render(spheres, K, Rs, ts, image_size, albedo, background, light, ambient, noise, rng, name):
    """Ray cast every view of the spheres (nearest hit, Lambertian shade), add pixel noise: a :class:`SphereScene`."""
    w, h = image_size
    yy, xx = np.mgrid[0:h, 0:w]
    pix_h = np.stack([xx.ravel(), yy.ravel(), np.ones(w * h)], axis=1).astype(float)
    scene = SphereScene(np.repeat(K[None], len(Rs), axis=0), Rs, ts, [], [], np.zeros((len(Rs), h, w)), spheres,
                        (w, h), noise, albedo, light, ambient, name)
    for v, (R, C) in enumerate(zip(Rs, scene.C)):
        d = pix_h @ np.linalg.inv(K).T @ R                 # ray directions in the world: Rᵀ K⁻¹ x
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        s, which = _first_hit(C, d, spheres)
        hit = which >= 0
        img = background(yy.ravel() / h)
        P = C + s[hit, None] * d[hit]
        normals = (P - spheres[which[hit], :3]) / spheres[which[hit], 3:]
        img[hit] = albedo(P, which[hit]) * scene._shade(normals)[:, None]
        if noise > 0:
            img += rng.normal(0.0, noise, img.shape)
        scene.images.append(np.clip(np.round(img), 0, 255).astype(np.uint8).reshape(h, w, 3))
        scene.masks.append(hit.reshape(h, w))
        depth = np.full(w * h, np.nan)
        depth[hit] = s[hit] * (d[hit] @ R[2])
        scene.depths[v] = depth.reshape(h, w)
    return scene


def _check(n_views, rng, image_size, f, noise, spheres, default):
    as_rng(rng)
    n_views = as_count(n_views, "n_views", 2)
    w, h = as_image_size(image_size, minimum=8)
    f = as_positive(f, "f")
    noise = as_positive(noise, "noise", allow_zero=True)
    spheres = default.copy() if spheres is None else np.asarray(spheres, float)
    if spheres.ndim != 2 or spheres.shape[1] != 4 or len(spheres) == 0 or not np.all(np.isfinite(spheres)) \
            or not np.all(spheres[:, 3] > 0):
        raise ValueError(f"spheres must be (M, 4) rows (x, y, z, radius > 0), finite; got {spheres.shape}")
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return n_views, (w, h), noise, spheres, K


def _gradient(top, bottom_gain=0.4):
    return lambda y: np.asarray(top, float) * (0.8 + bottom_gain * y)[:, None]


def _two_tones(upper, lower, horizon=0.55, bottom_gain=0.4):
    """A wall (``upper``) above a table (``lower``) meeting at ``horizon`` (a fraction of the height), both with the
    gradient of :func:`_gradient`; one tone when they are equal."""
    upper, lower = np.asarray(upper, float), np.asarray(lower, float)
    return lambda y: np.where((y < horizon)[:, None], upper, lower) * (0.8 + bottom_gain * y)[:, None]


def _as_rgb(value, name, rows):
    """An RGB colour (3,), or ``rows`` of them, each channel in [0, 255], as a (rows, 3) float array."""
    a = np.asarray(value, dtype=float)
    a = a[None] if a.shape == (3,) else a
    if a.ndim != 2 or a.shape[1] != 3 or len(a) not in rows or not np.all(np.isfinite(a)) or a.min() < 0 \
            or a.max() > 255:
        raise ValueError(f"{name} must be an RGB colour (3,){' or (2, 3): two tones' if 2 in rows else ''}, "
                         f"channels in [0, 255]; got {np.asarray(value).tolist()!r}")
    return a


_LIGHT = np.array([0.4, -0.3, 0.85]) / np.linalg.norm([0.4, -0.3, 0.85])


def make_snowman(n_views: int = 24, *, rng: np.random.Generator, image_size: tuple[int, int] = (320, 240),
                 f: float = 420.0, distance: float = 3.0, elevations: Sequence[float] = (15.0, 45.0),
                 noise: float = 2.0, spheres: ArrayLike | None = None, colour: ArrayLike = (235.0, 130.0, 40.0),
                 background: ArrayLike = (60.0, 75.0, 170.0)) -> SphereScene:
    """Cameras on rings around a plain orange snowman of spheres on a blue gradient (carving's test object).

    Parameters
    ----------
    n_views : int
        Views, split between the ``elevations`` (degrees above the ground plane z = 0), all looking at (0, 0, 0.3).
    rng : numpy.random.Generator
        Pixel noise (and nothing else: the cameras are on regular rings).
    image_size : (width, height)
    f : float
        Focal length, pixels (principal point at the image centre).
    distance : float
        Cameras' distance from (0, 0, 0.3).
    noise : float
        Standard deviation of the pixel noise, grey levels.
    spheres : (M, 4) array_like, optional
        Centre and radius of each sphere (default: :data:`SNOWMAN`).
    colour : (3,) array_like
        The object's paint, RGB in [0, 255] (lit fully; the shade goes down to 0.35 of it on the dark side).
    background : (3,) or (2, 3) array_like
        RGB of the background, or two tones: a wall (upper 55 % of the image) and a table; each darkens upwards
        (0.8 of it at the top, 1.2 at the bottom, clipped at 255).

    Returns
    -------
    SphereScene

    Examples
    --------
    >>> s = make_snowman(6, rng=np.random.default_rng(0), image_size=(64, 48), f=84.0)
    >>> s.P.shape, s.images[0].shape, s.images[0].dtype, bool(s.masks[0].any())
    ((6, 3, 4), (48, 64, 3), dtype('uint8'), True)
    >>> grey = make_snowman(2, rng=np.random.default_rng(0), image_size=(64, 48), f=84.0, colour=(200, 200, 200),
    ...                     background=[(10, 10, 10), (90, 90, 90)], noise=0)   # grey on a black wall, grey table
    >>> grey.images[0][0, 0].tolist(), grey.images[0][-1, 0].tolist()
    ([8, 8, 8], [107, 107, 107])
    """
    n_views, size, noise, spheres, K = _check(n_views, rng, image_size, f, noise, spheres, SNOWMAN)
    paint = _as_rgb(colour, "colour", (1,))[0]
    tones = _as_rgb(background, "background", (1, 2))
    R, t = _ring(n_views, np.array([0.0, 0.0, 0.3]), as_positive(distance, "distance"), elevations)
    return _render(spheres, K, R, t, size, lambda X, k: paint, _two_tones(tones[0], tones[-1]), _LIGHT, 0.35, noise,
                   rng, "snowman")


def _stripes(X, k):
    """Orange and yellow stripes around the vertical axis, with a green band: a texture with edges."""
    s = 0.5 + 0.5 * np.sin(24.0 * np.arctan2(X[:, 1], X[:, 0]) + 9.0 * X[:, 2])
    base = np.array([225.0, 110.0, 35.0]) * (1 - s)[:, None] + np.array([245.0, 215.0, 60.0]) * s[:, None]
    band = np.exp(-((X[:, 2] - 0.25) / 0.06) ** 2)[:, None]
    return base * (1 - band) + np.array([60.0, 150.0, 70.0]) * band


def make_textured_scene(n_views: int = 24, *, rng: np.random.Generator, image_size: tuple[int, int] = (320, 240),
                        f: float = 420.0, distance: float = 3.0, elevations: Sequence[float] = (15.0, 45.0),
                        noise: float = 2.0, spheres: ArrayLike | None = None) -> SphereScene:
    """The snowman of :func:`make_snowman` painted with stripes (points, normals and texture's test object).

    Parameters are those of :func:`make_snowman`; the paint is orange and yellow stripes around the vertical axis
    with a green band, so the colour a camera sees has edges, and :meth:`SphereScene.colour` gives it exactly.

    Returns
    -------
    SphereScene

    Examples
    --------
    >>> s = make_textured_scene(4, rng=np.random.default_rng(0), image_size=(64, 48), f=84.0)
    >>> X, n = s.surface_points(100, rng=np.random.default_rng(1))
    >>> s.images[0].shape, X.shape, bool(s.visibility(X, n).any(axis=0).mean() > 0.5)
    ((48, 64, 3), (100, 3), True)
    """
    n_views, size, noise, spheres, K = _check(n_views, rng, image_size, f, noise, spheres, SNOWMAN)
    R, t = _ring(n_views, np.array([0.0, 0.0, 0.3]), as_positive(distance, "distance"), elevations)
    return _render(spheres, K, R, t, size, _stripes, _gradient([60.0, 75.0, 170.0]), _LIGHT, 0.35, noise, rng,
                   "textured snowman")


def make_textured_spheres(n_views: int = 24, *, rng: np.random.Generator, image_size: tuple = (320, 240),
                          f: float = 560.0, distance: float = 2.5, elevation_deg: float = 20.0,
                          noise: float = 1.0) -> SphereScene:
    """Cameras on a ring around four spheres with 3-D wave textures on a dark background (dense stereo's object).

    Each sphere has a colour and a 3-D texture (a sum of plane waves of random direction, wavelength 0.03–0.1,
    random phase), times a Lambertian shade that is the same from every view; then Gaussian pixel noise.

    Parameters
    ----------
    n_views : int
        Views, evenly spaced on the ring (``360 / n_views`` degrees apart), looking at (0, 0, 0.2).
    rng : numpy.random.Generator
        Textures and pixel noise.
    image_size : (w, h)
    f : float
        Focal length in pixels (principal point at the image centre).
    distance, elevation_deg : float
        The ring's radius (from the target) and its elevation above the target's horizontal plane.
    noise : float
        Standard deviation of the pixel noise, grey levels.

    Returns
    -------
    SphereScene

    Examples
    --------
    >>> s = make_textured_spheres(4, rng=np.random.default_rng(0), image_size=(64, 48), f=84.0)
    >>> s.images[0].shape, s.depths.shape, bool(np.isfinite(s.depths[0]).any())
    ((48, 64, 3), (4, 48, 64), True)
    """
    n_views, size, noise, spheres, K = _check(n_views, rng, image_size, f, noise, None, SPHERES)
    waves = []
    for _ in spheres:
        direction = rng.normal(size=(16, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        wavelength = rng.uniform(0.03, 0.1, 16)
        waves.append(np.c_[direction * (2 * np.pi / wavelength)[:, None], rng.uniform(0, 2 * np.pi, 16)])
    colours = np.array([[230.0, 150, 70], [120, 200, 120], [110, 150, 240], [230, 110, 160]])

    def paint(X, k):
        tex = np.empty(len(X))
        for j, wv in enumerate(waves):
            on = k == j
            tex[on] = 0.5 + 0.5 * np.tanh(np.sin(X[on] @ wv[:, :3].T + wv[:, 3]).sum(axis=1) / np.sqrt(len(wv)))
        return colours[k] * (0.25 + 0.75 * tex)[:, None]

    R, t = _ring(n_views, np.array([0.0, 0.0, 0.2]), as_positive(distance, "distance"), (elevation_deg,))
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    return _render(spheres, K, R, t, size, paint, lambda y: np.full((len(y), 3), 40.0), light, 0.45, noise, rng,
                   "textured spheres")
