"""A rectified stereo pair with exact ground truth, for the tests and notebook 12: :func:`make_layered_pair`, textured
fronto-parallel layers with integer disparities. Every pixel's true disparity is known, and so is which left pixels
the right camera does not see (occlusions): the left–right check's test case. (The textured spheres seen by a ring of
cameras, with the true depth of every pixel, are :func:`labutils.model.make_textured_spheres`.)

Every random choice comes from the ``rng`` argument (a ``numpy.random.Generator``).
"""
from dataclasses import dataclass, field

import cv2
import numpy as np

from ...core.validation import as_count, as_image_size, as_positive, as_rng

__all__ = ["LayeredPair", "make_layered_pair"]


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
    w, h = as_image_size(image_size, minimum=16)
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
