"""Stereo scenes with exact ground truth, for the tests and as notebook 12's fallback.

- :func:`make_layered_pair`: a rectified pair of fronto-parallel textured layers with integer disparities. Every
  pixel's true disparity is known, and so is which left pixels the right camera does not see (occlusions): the
  left–right check's test case.
- :func:`make_textured_spheres`: cameras on a ring around textured spheres standing on nothing, ray-traced. The true
  depth of every pixel, the silhouettes, and points on the surface are known.

Every random choice comes from the ``rng`` argument (a ``numpy.random.Generator``).
"""
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ...core.scene import CameraRig
from ...core.synthetic import look_at
from ...core.validation import as_count, as_positive, as_rng
from ..carving.synthetic import _spheres_box

__all__ = ["LayeredPair", "make_layered_pair", "SphereScene", "make_textured_spheres"]


def _smooth_texture(shape, rng, sigma=1.2):
    """Random texture, 0..255, smoothed a little (like a real image, not white noise)."""
    t = cv2.GaussianBlur(rng.uniform(0, 1, shape), (0, 0), sigma)
    t = (t - t.min()) / max(np.ptp(t), 1e-12)
    return 30 + 200 * t


@dataclass
class LayeredPair:
    """A rectified pair of fronto-parallel layers with the truth.

    Attributes
    ----------
    left, right : (h, w) uint8 ndarray
    disparity_left, disparity_right : (h, w) ndarray
        True disparity ``x_left - x_right`` of each pixel of the left / right image (integers).
    occluded_left, occluded_right : (h, w) bool ndarray
        Pixels whose scene point the other camera does not see (hidden by a nearer layer, or out of its image).
    layers : (n, 5) ndarray
        ``(x0, y0, x1, y1, d)`` of each layer, in left-image pixels (the first is the whole background).
    """

    left: np.ndarray = field(repr=False)
    right: np.ndarray = field(repr=False)
    disparity_left: np.ndarray = field(repr=False)
    disparity_right: np.ndarray = field(repr=False)
    occluded_left: np.ndarray = field(repr=False)
    occluded_right: np.ndarray = field(repr=False)
    layers: np.ndarray


def make_layered_pair(*, rng: np.random.Generator, image_size: tuple = (160, 120), d_background: int = 4,
                      d_layers: tuple = (12, 20), noise: float = 0.0) -> LayeredPair:
    """A rectified pair of a textured background and nearer textured rectangles, with integer disparities.

    Each layer is a fronto-parallel plane with its own random texture ``T(y, u)``; the left image shows at ``(x, y)``
    the nearest layer covering it (``u = x``), the right image at ``(x_r, y)`` the nearest layer covering
    ``u = x_r + d`` (so ``x_r = x - d``). A left pixel is occluded when a nearer layer covers its point in the right
    image, or its point falls outside the right image.

    Parameters
    ----------
    rng : numpy.random.Generator
        Textures, the rectangles' places, the noise.
    image_size : (w, h)
    d_background : int
        The background's disparity.
    d_layers : tuple of int
        The rectangles' disparities, each larger than ``d_background`` (nearer).
    noise : float
        Standard deviation of the Gaussian pixel noise, grey levels (independent in the two images).

    Returns
    -------
    LayeredPair

    Examples
    --------
    >>> p = make_layered_pair(rng=np.random.default_rng(0))
    >>> p.left.shape, int(p.disparity_left.max()), bool(p.occluded_left.any())
    ((120, 160), 20, True)
    """
    rng = as_rng(rng)
    w, h = (as_count(v, "image_size", 16) for v in image_size)
    d_bg = as_count(d_background, "d_background", 0)
    ds = [as_count(d, "d_layers", d_bg + 1) for d in d_layers]
    noise = as_positive(noise, "noise", allow_zero=True)
    layers = [(0, 0, w + max([d_bg, *ds]), h, d_bg)]        # the background covers everything the cameras see
    for d in ds:
        lw, lh = int(rng.integers(w // 5, w // 3)), int(rng.integers(h // 4, h // 2))
        x0, y0 = int(rng.integers(w // 8, w - lw - w // 8 + 1)), int(rng.integers(h // 8, h - lh - h // 8 + 1))
        layers.append((x0, y0, x0 + lw, y0 + lh, d))
    layers = np.array(layers, dtype=int)
    order = np.argsort(layers[:, 4], kind="stable")          # far to near: the nearer layer paints over
    W = w + int(layers[:, 4].max()) + 1
    textures = [_smooth_texture((h, W), rng) for _ in layers]
    xs, ys = np.meshgrid(np.arange(w), np.arange(h))

    def render(u_of_x):
        img, disp, layer_id = np.zeros((h, w)), np.zeros((h, w)), np.full((h, w), -1)
        for k in order:
            x0, y0, x1, y1, d = layers[k]
            u = u_of_x(xs, d)
            cover = (u >= x0) & (u < x1) & (ys >= y0) & (ys < y1)
            img[cover] = textures[k][ys[cover], u[cover]]
            disp[cover], layer_id[cover] = d, k
        return img, disp, layer_id

    left, d_left, id_left = render(lambda x, d: x)
    right, d_right, id_right = render(lambda x, d: x + d)
    xr = xs - d_left.astype(int)                               # where each left pixel's point is in the right image
    inside = xr >= 0
    occ_left = ~inside
    occ_left[inside] = id_right[ys[inside], xr[inside]] != id_left[inside]
    xl = xs + d_right.astype(int)
    inside = xl < w
    occ_right = ~inside
    occ_right[inside] = id_left[ys[inside], xl[inside]] != id_right[inside]

    def to_uint8(img):
        return np.clip(np.round(img + rng.normal(0.0, noise, img.shape) if noise else img), 0, 255).astype(np.uint8)

    return LayeredPair(to_uint8(left), to_uint8(right), d_left, d_right, occ_left, occ_right, layers)


SPHERES = np.array([[0.0, 0.0, 0.0, 0.30], [0.0, 0.0, 0.42, 0.20], [0.22, 0.12, 0.05, 0.12], [-0.2, -0.16, 0.1, 0.1]])
"""Centre and radius of each sphere of the default scene (world units)."""


@dataclass
class SphereScene(CameraRig):
    """Textured spheres seen by cameras on a ring, with the truth.

    Attributes
    ----------
    K : (V, 3, 3) ndarray
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        ``x_cam = R @ X + t``.
    images : list of (h, w, 3) uint8 ndarray
    depths : (V, h, w) ndarray
        True depth of each pixel (along the camera's z axis), NaN on the background.
    spheres : (M, 4) ndarray
        Centre and radius of each sphere.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    images: list = field(repr=False)
    depths: np.ndarray = field(repr=False)
    spheres: np.ndarray = field(default_factory=lambda: SPHERES.copy())
    name: str = "textured spheres"
    source: str = "synthetic"

    @property
    def masks(self):
        """The exact silhouettes, ``(h, w)`` bool per view."""
        return [np.isfinite(d) for d in self.depths]

    @property
    def box(self):
        """(2, 3): the tight box around the spheres."""
        return _spheres_box(self.spheres)

    def distance_to_surface(self, X: ArrayLike) -> np.ndarray:
        """(N,) signed distance of points to the union of the spheres' surfaces (negative inside)."""
        X = np.asarray(X, float).reshape(-1, 3)
        return np.min(np.linalg.norm(X[:, None] - self.spheres[None, :, :3], axis=2) - self.spheres[:, 3], axis=1)

    def visible(self, X: ArrayLike, rel_tol: float = 1e-3) -> np.ndarray:
        """(V, N) bool: which views see each point — it projects into the image and the true depth at its pixel is
        its own depth (within ``rel_tol`` relative, plus two pixels' footprint for the slope across a pixel), so
        nothing nearer hides it. Meant for points on the surface."""
        X = np.asarray(X, float).reshape(-1, 3)
        h, w = self.depths.shape[1:]
        out = np.zeros((self.n_views, len(X)), bool)
        for v in range(self.n_views):
            xc = X @ self.R[v].T + self.t[v]
            u = xc @ self.K[v].T
            with np.errstate(divide="ignore", invalid="ignore"):
                c, r = np.floor(u[:, 0] / u[:, 2] + 0.5), np.floor(u[:, 1] / u[:, 2] + 0.5)
            ok = (xc[:, 2] > 0) & (c >= 0) & (c < w) & (r >= 0) & (r < h)
            z = self.depths[v][r[ok].astype(int), c[ok].astype(int)]
            with np.errstate(invalid="ignore"):
                out[v, ok] = np.abs(z - xc[ok, 2]) <= rel_tol * xc[ok, 2] + 2 * xc[ok, 2] / self.K[v, 0, 0]
        return out

    def surface_points(self, n: int, *, rng: np.random.Generator) -> np.ndarray:
        """(n, 3) random points on the visible surface: on a sphere, outside every other sphere, above the lowest."""
        rng = as_rng(rng)
        n = as_count(n, "n")
        out = []
        while sum(len(o) for o in out) < n:
            k = rng.integers(0, len(self.spheres), 4 * n)
            d = rng.normal(size=(4 * n, 3))
            X = self.spheres[k, :3] + self.spheres[k, 3:] * d / np.linalg.norm(d, axis=1, keepdims=True)
            out.append(X[self.distance_to_surface(X) > -1e-9])
        return np.concatenate(out)[:n]


def _texture(X, waves):
    """A smooth 3-D texture: a sum of plane waves, 0..1."""
    v = np.sin(X @ waves[:, :3].T + waves[:, 3]).sum(axis=1)
    return 0.5 + 0.5 * np.tanh(v / np.sqrt(len(waves)))


def make_textured_spheres(n_views: int = 24, *, rng: np.random.Generator, image_size: tuple = (320, 240),
                          f: float = 560.0, distance: float = 2.5, elevation_deg: float = 20.0,
                          noise: float = 1.0) -> SphereScene:
    """Cameras on a ring (looking at the spheres' centre) and the ray-traced images of four textured spheres.

    Each sphere has a colour and a 3-D texture (a sum of plane waves of random direction, wavelength 0.03–0.1,
    random phase), times a Lambertian shade that is the same from every view, on a dark grey background; then
    Gaussian pixel noise.

    Parameters
    ----------
    n_views : int
        Views, evenly spaced on the ring (``360 / n_views`` degrees apart).
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
    rng = as_rng(rng)
    n_views = as_count(n_views, "n_views", 2)
    w, h = (as_count(v, "image_size", 8) for v in image_size)
    f = as_positive(f, "f")
    distance = as_positive(distance, "distance")
    noise = as_positive(noise, "noise", allow_zero=True)
    spheres = SPHERES.copy()
    target = np.array([0.0, 0.0, 0.2])
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    n_waves = 16
    waves = []
    for _ in spheres:
        direction = rng.normal(size=(n_waves, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        wavelength = rng.uniform(0.03, 0.1, n_waves)
        waves.append(np.c_[direction * (2 * np.pi / wavelength)[:, None], rng.uniform(0, 2 * np.pi, n_waves)])
    colours = np.array([[230.0, 150, 70], [120, 200, 120], [110, 150, 240], [230, 110, 160]])
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    e = np.deg2rad(elevation_deg)
    yy, xx = np.mgrid[0:h, 0:w]
    pix_h = np.stack([xx.ravel(), yy.ravel(), np.ones(w * h)], axis=1).astype(float)
    Rs, ts, images, depths = [], [], [], []
    for v in range(n_views):
        a = 2 * np.pi * v / n_views
        C = target + distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        R, t = look_at(C, target)
        rays = pix_h @ np.linalg.inv(K).T                      # camera frame, z = 1: the hit's depth is s
        d = rays @ R                                           # world directions Rᵀ r (not unit)
        best = np.full(len(d), np.inf)
        which = np.full(len(d), -1)
        A = np.einsum("ij,ij->i", d, d)
        for k, (S, r) in enumerate(zip(spheres[:, :3], spheres[:, 3])):
            q = C - S
            B, Cq = 2 * d @ q, q @ q - r * r
            disc = B * B - 4 * A * Cq
            s = np.where(disc > 0, (-B - np.sqrt(np.maximum(disc, 0))) / (2 * A), np.inf)
            hit = (s > 0) & (s < best)
            best[hit], which[hit] = s[hit], k
        img = np.full((w * h, 3), 40.0)
        hit = which >= 0
        X = C + best[hit, None] * d[hit]
        normal = (X - spheres[which[hit], :3]) / spheres[which[hit], 3:]
        shade = 0.45 + 0.55 * np.clip(normal @ light, 0, 1)
        tex = np.empty(len(X))
        for k in range(len(spheres)):
            on = which[hit] == k
            tex[on] = _texture(X[on], waves[k])
        img[hit] = colours[which[hit]] * (0.25 + 0.75 * tex)[:, None] * shade[:, None]
        img += rng.normal(0.0, noise, img.shape) if noise else 0.0
        images.append(np.clip(np.round(img), 0, 255).astype(np.uint8).reshape(h, w, 3))
        depth = np.full(w * h, np.nan)
        depth[hit] = best[hit]
        depths.append(depth.reshape(h, w))
        Rs.append(R)
        ts.append(t)
    return SphereScene(np.repeat(K[None], n_views, axis=0), np.array(Rs), np.array(ts), images, np.array(depths),
                       spheres)
