"""Images for matching: reading a grey image (reduced if asked), and the pixel and K conversions between a reduced
image and the original."""
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ..core.validation import as_positive

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
"""The image files :func:`labutils.match.cli` reads (case-insensitive)."""


# ---------------------------------------------------------------------------------------------
# Images and pixel scales
# ---------------------------------------------------------------------------------------------

def scale_calibration(K: ArrayLike, scale: float) -> np.ndarray:
    """The calibration of an image reduced (or enlarged) by ``scale``, with OpenCV's pixel centres.

    A pixel ``x`` of the original lands at ``s (x + 0.5) - 0.5`` in the scaled image, so
    ``K_s = [[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1]] @ K``. Scaling K by ``diag(s, s, 1)``
    alone moves the principal point by half a pixel of the original image (``(1 - s) / 2`` pixels of
    the reduced one): small, but it costs accuracy (notebook 07 measures it).

    Parameters
    ----------
    K : (3, 3) or (V, 3, 3) array_like
    scale : float
        New size / original size.

    Returns
    -------
    K_s : ndarray, the shape of ``K``

    Examples
    --------
    >>> scale_calibration(np.diag([1000.0, 1000.0, 1.0]), 0.5)
    array([[ 5.0e+02,  0.0e+00, -2.5e-01],
           [ 0.0e+00,  5.0e+02, -2.5e-01],
           [ 0.0e+00,  0.0e+00,  1.0e+00]])
    """
    K = np.asarray(K, float)
    if K.shape[-2:] != (3, 3) or K.ndim not in (2, 3):
        raise ValueError(f"K must have shape (3, 3) or (V, 3, 3); got {K.shape}")
    scale = as_positive(scale, "scale")
    S = np.array([[scale, 0.0, (scale - 1) / 2], [0.0, scale, (scale - 1) / 2], [0.0, 0.0, 1.0]])
    return S @ K


def _as_pixels(x, name):
    x = np.asarray(x, float)
    if x.ndim < 1 or x.shape[-1] != 2:
        raise ValueError(f"{name} must have shape (..., 2) (pixels as rows, NaN allowed for unseen); got {x.shape}")
    return x


def to_original_pixels(x: ArrayLike, scale: float) -> np.ndarray:
    """Pixels of an image scaled by ``scale`` back to the original: ``(x + 0.5) / s - 0.5``.

    ``x`` has shape ``(..., 2)``; NaN (unseen) stays NaN. ``scale`` must be a positive number (``ValueError``).

    >>> to_original_pixels([[0.0, 1.5], [np.nan, np.nan]], 0.5)
    array([[0.5, 3.5],
           [nan, nan]])
    """
    return (_as_pixels(x, "x") + 0.5) / as_positive(scale, "scale") - 0.5


def to_working_pixels(x: ArrayLike, scale: float) -> np.ndarray:
    """Pixels of the original image in an image scaled by ``scale``: ``s (x + 0.5) - 0.5``.

    >>> to_working_pixels(to_original_pixels([[3.0, 7.0]], 0.25), 0.25)
    array([[3., 7.]])
    """
    return as_positive(scale, "scale") * (_as_pixels(x, "x") + 0.5) - 0.5


def resize_gray(image: ArrayLike, max_size: int | None = None) -> tuple[np.ndarray, float]:
    """A grey copy of ``image`` whose longer side is at most ``max_size``, and the scale used.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 array_like
        Grey or RGB.
    max_size : int, optional
        Longest side in pixels; None keeps the size. Images are only ever reduced (area averaging).

    Returns
    -------
    gray : (h, w) uint8 ndarray
    scale : float
        ``h / H`` (the same for both axes: OpenCV's resize is given the factor, not the size).

    Examples
    --------
    >>> g, s = resize_gray(np.zeros((400, 600, 3), np.uint8), max_size=300)
    >>> g.shape, s
    ((200, 300), 0.5)
    """
    try:
        img = np.asarray(image)
    except ValueError as exc:
        raise ValueError(f"image must be a (H, W) or (H, W, 3) uint8 array: {exc}") from None
    if not (img.ndim == 2 or img.ndim == 3 and img.shape[2] == 3) or img.size == 0:
        raise ValueError(f"image must have shape (H, W) or (H, W, 3) with H, W > 0; got {img.shape}")
    if img.dtype != np.uint8:        # a float image in [0, 1] cast to uint8 would be black: no keypoints, no error
        raise ValueError(f"image must be uint8 (0..255); got dtype {img.dtype} (convert it yourself, e.g. "
                         "np.clip(255 * img, 0, 255).astype(np.uint8) for a float image in [0, 1])")
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    img = np.ascontiguousarray(img)
    if max_size is None or max(img.shape) <= max_size:
        return img, 1.0
    if max_size < 16:
        raise ValueError(f"max_size must be at least 16 pixels; got {max_size}")
    s = max_size / max(img.shape)
    return cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA), s


def read_gray(path: str | Path, max_size: int | None = None) -> tuple[np.ndarray, float, tuple[int, int]]:
    """Read an image file as grey, reduced so that its longer side is at most ``max_size``.

    JPEG files are decoded directly at 1/2, 1/4 or 1/8 of their size when that is still at least the
    target (libjpeg's scaled decoding, much faster than decoding the full image; it averages blocks,
    which keeps the pixel-centre convention of :func:`scale_calibration`), then area-averaged to the
    target.

    Parameters
    ----------
    path : str or Path
    max_size : int, optional

    Returns
    -------
    gray : (h, w) uint8 ndarray
    scale : float
        Size of ``gray`` / size of the original image.
    original_size : (width, height)

    Raises
    ------
    ValueError
        If the file cannot be read as an image (the message names the file).
    """
    path = Path(path)
    full = None
    reduce = 1
    if path.suffix.lower() in (".jpg", ".jpeg") and max_size is not None:
        header = cv2.imread(str(path), cv2.IMREAD_REDUCED_GRAYSCALE_8)
        if header is None:
            raise ValueError(f"{path}: cannot read the image (not a PNG/JPEG file, or damaged)")
        approx_long = 8 * max(header.shape)          # the full size to within 7 pixels
        for r, flag in ((8, cv2.IMREAD_REDUCED_GRAYSCALE_8), (4, cv2.IMREAD_REDUCED_GRAYSCALE_4),
                        (2, cv2.IMREAD_REDUCED_GRAYSCALE_2)):
            if approx_long / r >= max_size + 8:
                full = header if r == 8 else cv2.imread(str(path), flag)
                reduce = r
                break
    if full is None:
        full = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        reduce = 1
    if full is None:
        raise ValueError(f"{path}: cannot read the image (not a PNG/JPEG file, or damaged)")
    original = (full.shape[1] * reduce, full.shape[0] * reduce)
    if reduce > 1:        # the exact original size: the header, read cheaply
        original = _jpeg_size(path) or original
    target = None if max_size is None else max_size
    gray, s = resize_gray(full, target)
    return gray, s / reduce, original


def _jpeg_size(path):
    """(width, height) from a JPEG's SOF header, or None."""
    data = Path(path).read_bytes()
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            return None
        marker, length = data[i + 1], int.from_bytes(data[i + 2:i + 4], "big")
        if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF):
            h, w = int.from_bytes(data[i + 5:i + 7], "big"), int.from_bytes(data[i + 7:i + 9], "big")
            return (w, h)
        i += 2 + length
    return None
