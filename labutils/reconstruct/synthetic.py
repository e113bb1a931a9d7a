"""Photos with a known camera and lens, for testing the reconstruction without photos of ours: the textured box
corner of :func:`labutils.match.synthetic.render_corner`, distorted by a known radial lens and saved as PNG files."""
from pathlib import Path

import cv2
import numpy as np

from ..calibrate.lens import undistort_normalised
from ..core.validation import as_rng
from ..match.synthetic import render_corner

__all__ = ["render_photo_folder"]


def distort_image(image, K, dist):
    """The image a lens with radial ``dist = (k1, k2)`` would have taken: pixel ``u_d`` shows what the pinhole image
    shows at ``K · undistort(K⁻¹ u_d)``."""
    H, W = image.shape[:2]
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    xd = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]], -1).reshape(-1, 2)
    xu = undistort_normalised(xd, [dist[0], dist[1], 0.0, 0.0, 0.0])
    mx = (xu[:, 0] * K[0, 0] + K[0, 2]).reshape(H, W).astype(np.float32)
    my = (xu[:, 1] * K[1, 1] + K[1, 2]).reshape(H, W).astype(np.float32)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR)


def render_photo_folder(folder, *, rng, n_views=6, image_size=(480, 360), dist=(-0.2, 0.0)):
    """Render ``n_views`` photos of the box corner through a lens ``dist = (k1, k2)`` into ``folder`` (PNG files
    ``000.png``, ...); returns the :class:`~labutils.match.synthetic.RenderedScene` (its K, R, t are the truth).

    >>> import tempfile
    >>> s = render_photo_folder(tempfile.mkdtemp(), rng=np.random.default_rng(0), n_views=2, image_size=(64, 48))
    >>> s.n_views, s.K.shape
    (2, (3, 3))
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"{folder}: not a folder")
    dist = np.asarray(dist, float)
    if dist.shape != (2,) or not np.all(np.isfinite(dist)):
        raise ValueError(f"dist must be 2 finite numbers (k1, k2); got {dist!r}")
    s = render_corner(n_views, image_size, rng=as_rng(rng), arc_deg=60, texture_px=768)
    for i, img in enumerate(s.images):
        cv2.imwrite(str(folder / f"{i:03d}.png"), distort_image(img, s.K, dist))
    return s
