"""Synthetic images with known geometry: textured planes rendered from known cameras.

For testing feature matching (and as the fallback of notebook 07 when no real images are on the data
path) we need images whose correspondences are known exactly. :func:`render_corner` builds the inside
corner of a box: three mutually orthogonal unit squares (a floor and two walls) covered with random
blob textures, seen from cameras on an arc in front of it. From inside a concave corner no face hides
another, so every pixel that shows a face has exactly one 3D point, :meth:`RenderedScene.points_3d`,
and its true position in every other view is a projection away.

Rendering is a homography per face (H&Z Sec. 13.1: a plane induces ``x ≃ K [R a, R b, R o + t] (u, v, 1)``
for the face ``o + u a + v b``), done by OpenCV's ``warpPerspective``.
"""
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ..core.synthetic import look_at
from ..core.validation import as_count, as_image_size, as_points, as_rng

__all__ = ["RenderedScene", "render_corner", "blob_texture", "look_at"]

# the three faces of the corner: origin o and edge vectors a, b (unit square o + u a + v b, u, v in [0, 1])
CORNER_FACES = (
    (np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])),    # floor z = 0
    (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -1.0])),   # wall y = 0
    (np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, -1.0])),   # wall x = 0
)


def blob_texture(size: int, *, rng: np.random.Generator, n_blobs: int = 400,
                 radius: tuple[float, float] = (0.006, 0.05)) -> np.ndarray:
    """A grey texture of random discs and rectangles at several scales, lightly blurred: many SIFT blobs.

    Parameters
    ----------
    size : int
        Side in pixels.
    rng : numpy.random.Generator
    n_blobs : int
    radius : (float, float)
        Smallest and largest blob radius, as a fraction of ``size`` (drawn log-uniformly).

    Returns
    -------
    (size, size) uint8 ndarray

    Examples
    --------
    >>> blob_texture(64, rng=np.random.default_rng(0)).shape
    (64, 64)
    """
    import cv2

    as_rng(rng)
    img = np.full((size, size), 128, np.uint8)
    for _ in range(int(n_blobs)):
        c = rng.integers(0, size, 2)
        r = int(round(size * np.exp(rng.uniform(np.log(radius[0]), np.log(radius[1])))))
        grey = int(rng.integers(0, 256))
        if rng.random() < 0.6:
            cv2.circle(img, (int(c[0]), int(c[1])), max(r, 1), grey, -1, lineType=cv2.LINE_AA)
        else:
            cv2.rectangle(img, (int(c[0] - r), int(c[1] - r)), (int(c[0] + r), int(c[1] + r // 2)), grey, -1)
    return cv2.GaussianBlur(img, (0, 0), max(size / 512, 0.8))


@dataclass
class RenderedScene:
    """Images of textured planes with their exact cameras.

    Attributes
    ----------
    images : list of (H, W) uint8 ndarray
    K : (3, 3) ndarray
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        ``x_cam = R[i] @ X + t[i]``.
    faces : list of (o, a, b)
        Each face is the square ``o + u a + v b``, ``u, v`` in [0, 1].
    labels : list of (H, W) int8 ndarray
        Which face each pixel shows (-1: background).
    """

    images: list
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    faces: list = field(repr=False)
    labels: list = field(repr=False)

    @property
    def n_views(self):
        return len(self.images)

    @property
    def image_size(self):
        """(width, height)."""
        return (self.images[0].shape[1], self.images[0].shape[0])

    def points_3d(self, view: int, x: ArrayLike) -> np.ndarray:
        """The 3D points seen at pixels ``x`` (N, 2) of ``view``: the ray meets the face shown there.

        Returns
        -------
        X : (N, 3) ndarray
            NaN where the pixel shows background (or lies outside the image, or on a face's edge).
        """
        x = as_points(x, "x", min_n=0)
        X = np.full((len(x), 3), np.nan)
        lab = self.labels[view]
        h, w = lab.shape
        ij = np.round(x).astype(int)
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
        face = np.full(len(x), -1)
        face[inside] = lab[ij[inside, 1], ij[inside, 0]]
        R, t = self.R[view], self.t[view]
        C = -R.T @ t
        rays = (np.hstack([x, np.ones((len(x), 1))]) @ np.linalg.inv(self.K).T) @ R      # world directions
        for k, (o, a, b) in enumerate(self.faces):
            sel = face == k
            if not sel.any():
                continue
            n = np.cross(a, b)
            lam = ((o - C) @ n) / (rays[sel] @ n)
            X[sel] = C + lam[:, None] * rays[sel]
        return X

    def project(self, view: int, X: ArrayLike) -> np.ndarray:
        """Pixels of world points ``X`` (N, 3) in ``view`` (NaN stays NaN)."""
        X = np.asarray(X, float)
        y = (X @ self.R[view].T + self.t[view]) @ self.K.T
        return y[:, :2] / y[:, 2:]

    def transfer(self, i: int, j: int, x: ArrayLike) -> np.ndarray:
        """The true positions in view ``j`` of pixels ``x`` of view ``i`` (NaN where unknown)."""
        return self.project(j, self.points_3d(i, x))


def render_corner(n_views: int = 6, image_size: tuple[int, int] = (320, 240), *, rng: np.random.Generator,
                  arc_deg: float = 50.0, distance: float = 2.6, height: float = 1.6, texture_px: int = 768,
                  n_blobs: int = 400, radius: tuple[float, float] = (0.006, 0.05),
                  noise_grey: float = 1.0) -> RenderedScene:
    """Render the inside corner of a box (three textured unit squares) from ``n_views`` cameras on an arc.

    The cameras stand at ``distance`` from the corner's vertical axis and ``height`` above the floor,
    spread over ``arc_deg`` degrees around the diagonal direction (45°), all looking at the point
    (0.3, 0.3, 0.3).

    Parameters
    ----------
    n_views : int
    image_size : (width, height)
    rng : numpy.random.Generator
        Textures and image noise.
    arc_deg : float
        The arc the cameras span.
    distance, height : float
    texture_px : int
        Texture resolution per face.
    n_blobs, radius :
        Of each face's :func:`blob_texture`.
    noise_grey : float
        Standard deviation of the Gaussian noise added to each image (grey levels).

    Returns
    -------
    RenderedScene

    Examples
    --------
    >>> s = render_corner(3, (160, 120), rng=np.random.default_rng(0), texture_px=256)
    >>> s.n_views, s.images[0].shape, s.image_size
    (3, (120, 160), (160, 120))
    >>> x = np.array([[80.0, 60.0]]); X = s.points_3d(0, x)
    >>> bool(np.allclose(s.project(0, X), x))
    True
    """
    import cv2

    as_rng(rng)
    n_views = as_count(n_views, "n_views", 2)
    texture_px = as_count(texture_px, "texture_px", 2)
    w, h = as_image_size(image_size)
    f = 1.1 * w
    K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
    angles = np.radians(45.0 + np.linspace(-arc_deg / 2, arc_deg / 2, int(n_views)))
    target = np.array([0.3, 0.3, 0.3])
    Rs, ts = [], []
    for a in angles:
        R, t = look_at([distance * np.cos(a), distance * np.sin(a), height], target)
        Rs.append(R)
        ts.append(t)
    textures = [blob_texture(texture_px, rng=rng, n_blobs=n_blobs, radius=radius) for _ in CORNER_FACES]
    S = texture_px
    M = np.array([[1.0 / S, 0.0, 0.5 / S], [0.0, 1.0 / S, 0.5 / S], [0.0, 0.0, 1.0]])   # texture px -> (u, v)
    images, labels = [], []
    for R, t in zip(Rs, ts):
        img = np.zeros((h, w), np.float32)
        lab = np.full((h, w), -1, np.int8)
        for k, ((o, a, b), tex) in enumerate(zip(CORNER_FACES, textures)):
            H = K @ np.column_stack([R @ a, R @ b, R @ o + t]) @ M
            warped = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            cover = cv2.warpPerspective(np.full_like(tex, 255), H, (w, h), flags=cv2.INTER_NEAREST,
                                        borderMode=cv2.BORDER_CONSTANT) > 0
            img[cover] = warped[cover]
            lab[cover] = k
        img += rng.normal(0.0, noise_grey, img.shape).astype(np.float32)
        images.append(np.clip(np.round(img), 0, 255).astype(np.uint8))
        labels.append(lab)
    return RenderedScene(images=images, K=K, R=np.stack(Rs), t=np.stack(ts), faces=list(CORNER_FACES),
                         labels=labels)
