"""Undistorting images and rectifying a calibrated stereo pair (Fusiello, Trucco & Verri 2000; H&Z Sec. 11.12).

- :func:`remap_grid` / :func:`undistort_image`: the ideal pinhole image of a camera with lens distortion. For each
  pixel of the *output* image we compute where it came from in the *input* image (inverse mapping: output pixel →
  ideal normalised point → :func:`labutils.calibrate.distort` → input pixel) and let ``cv2.remap`` interpolate.
  No inversion of the distortion is needed this way round.
- :func:`rectify_fusiello`: rectifying homographies for a calibrated pair. Both cameras are turned (about their
  centres) to one common orientation whose x axis is the baseline, and given one common K. Then corresponding
  points lie on the same image row: the epipoles are at infinity along x, and ``F`` of the rectified pair is
  ``[(1, 0, 0)]×``, the F of a pure translation along x (H&Z Sec. 9.3.1 and 11.12).
- :func:`rectify_points`, :func:`rectify_image`: apply it to pixels and to images (with the distortion undone on
  the way).

Conventions: ``x_cam2 = R @ x_cam1 + t`` (camera 2 relative to camera 1, as
:class:`labutils.calibrate.StereoCalibration`), pixel centres at integer coordinates, image size ``(w, h)``.
"""
from dataclasses import dataclass

import cv2
import numpy as np

from ..core.validation import as_array, as_image, as_image_size, as_matrix, as_points, as_rotation
from .lens import as_distortion, as_intrinsics, distort, undistort_points

__all__ = ["remap_grid", "undistort_image", "Rectification", "rectify_fusiello", "rectify_points", "rectify_image"]


def _fold_radius(dist, r_max=3.0):
    """Smallest radius where the radial map ``r (1 + k1 r² + k2 r⁴ + k3 r⁶)`` stops increasing (``r_max`` if never).

    >>> round(_fold_radius([-0.5, 0, 0, 0, 0]), 3)       # d/dr (r - 0.5 r³) = 1 - 1.5 r² = 0 at r = 0.8165
    0.816
    """
    k1, k2, _, _, k3 = as_distortion(dist)
    r = np.linspace(0.0, r_max, 30001)
    slope = 1 + 3 * k1 * r ** 2 + 5 * k2 * r ** 4 + 7 * k3 * r ** 6
    bad = np.flatnonzero(slope <= 0)
    return float(r[bad[0] - 1]) if bad.size else float(r_max)


def remap_grid(K, dist, image_size, H=None, out_size=None):
    """For each output pixel, the input pixel it comes from: maps for ``cv2.remap``.

    The output image is the ideal (distortion-free) camera ``K`` followed by the homography ``H`` (identity:
    plain undistortion; ``K_new K⁻¹``: undistortion into another pinhole camera; a rectifying homography).
    Output pixel ``p`` → ``u = H⁻¹ p`` (ideal pixel of K) → ``x_n = K⁻¹ u`` → ``x_d =`` distort(x_n) → ``K x_d``.

    Parameters
    ----------
    K : (3, 3) array_like
    dist : (5,) array_like
    image_size : (w, h)
        Of the input image.
    H : (3, 3) array_like, optional
    out_size : (w, h), optional
        Of the output image (default ``image_size``).

    Returns
    -------
    map_x, map_y : (h_out, w_out) float32 ndarray

    Examples
    --------
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]])
    >>> mx, my = remap_grid(K, np.zeros(5), (640, 480))
    >>> float(mx[10, 20]), float(my[10, 20])
    (20.0, 10.0)
    """
    K = as_intrinsics(K)
    dist = as_distortion(dist)
    w, h = as_image_size(image_size)
    if out_size is not None:
        w, h = as_image_size(out_size, "out_size")
    Hinv = np.linalg.inv(np.eye(3) if H is None else as_matrix(H, "H", (3, 3)))
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    M = np.linalg.inv(K) @ Hinv
    u, v = u.ravel(), v.ravel()
    q = np.stack([M[i, 0] * u + M[i, 1] * v + M[i, 2] for i in range(3)], 1)     # (no BLAS: see bundle's note)
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = q[:, :2] / q[:, 2:]
    invalid = ~(q[:, 2] > 0) | ~np.all(np.isfinite(xn), axis=1)      # rays behind the camera
    # beyond the radius where r·(1 + k1 r² + k2 r⁴ + k3 r⁶) stops increasing, the polynomial folds back into the
    # image and would paint ghosts: map those pixels outside the input (cv2.remap fills them with the border)
    invalid |= (xn ** 2).sum(1) > _fold_radius(dist) ** 2
    xn[invalid] = 0.0
    xd = distort(xn, dist)
    src = xd @ K[:2, :2].T + K[:2, 2]                  # K's skew too (the dinosaur's is -78.6)
    src[invalid] = -1e4
    return src[:, 0].reshape(h, w).astype(np.float32), src[:, 1].reshape(h, w).astype(np.float32)


def undistort_image(image, K, dist, K_new=None):
    """The image an ideal pinhole camera ``K_new`` (default ``K``) at the same place would take.

    Straight lines in the world become straight in the output. Pixels that come from outside the input are black.

    Parameters
    ----------
    image : (h, w) or (h, w, 3) ndarray
    K : (3, 3) array_like
    dist : (5,) array_like
    K_new : (3, 3) array_like, optional

    Returns
    -------
    ndarray, like ``image``
    """
    image = as_image(image, "image")
    h, w = image.shape[:2]
    K = as_intrinsics(K)
    H = None if K_new is None else as_intrinsics(K_new, "K_new") @ np.linalg.inv(K)
    mx, my = remap_grid(K, dist, (w, h), H)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


@dataclass
class Rectification:
    """Rectifying homographies of a calibrated pair and the rectified cameras.

    Attributes
    ----------
    H1, H2 : (3, 3) ndarray
        Ideal (undistorted) pixels of camera 1 / 2 → rectified pixels.
    K_new : (3, 3) ndarray
        The common calibration of both rectified cameras.
    R_rect : (3, 3) ndarray
        The common orientation: a rectified camera's axes are ``R_rect @ x_cam1`` (its x axis is the baseline).
    P1, P2 : (3, 4) ndarray
        The rectified cameras in camera 1's frame: ``K_new [R_rect | 0]`` and ``K_new [R_rect | -R_rect C2]``.
    baseline : float
        ``|C2|``, in the units of t; disparity ``x1 - x2 = f · baseline / depth``.
    """

    H1: np.ndarray
    H2: np.ndarray
    K_new: np.ndarray
    R_rect: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    baseline: float


def rectify_fusiello(K1, K2, R, t, image_size=None):
    """Rectify a calibrated stereo pair (Fusiello, Trucco & Verri, "A compact algorithm for rectification of
    stereo pairs", MVA 12, 2000).

    The new common orientation ``R_rect`` has rows
    ``x = (C2 - C1) / |C2 - C1|`` (the baseline: epipolar lines become horizontal),
    ``y = z1 × x`` (z1: camera 1's old optical axis; so y is as close to "down" as possible) and ``z = x × y``.
    Both rectified cameras get ``K_new``: zero skew, the mean of the two focal lengths ``fy``, and a principal point
    that puts the mean of the two mapped image centres at the output image's centre (when ``image_size`` is given).
    The homographies are ``H1 = K_new R_rect K1⁻¹`` and ``H2 = K_new R_rect Rᵀ K2⁻¹``: each camera turns about its
    centre, which a homography of the (ideal) image can do (H&Z Sec. 8.4.2).

    Parameters
    ----------
    K1, K2 : (3, 3) array_like
    R : (3, 3) array_like
    t : (3,) array_like
        Camera 2 relative to camera 1: ``x_cam2 = R @ x_cam1 + t`` (t ≠ 0).
    image_size : (w, h), optional

    Returns
    -------
    Rectification

    Examples
    --------
    >>> from labutils.core.geometry import rotation_from_angle_axis
    >>> K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]]); R = rotation_from_angle_axis([0.02, -0.1, 0.01])
    >>> rect = rectify_fusiello(K, K, R, [-0.1, 0.005, 0.01])
    >>> X = np.array([[0.3, -0.2, 2.0], [-0.4, 0.3, 3.0]])
    >>> x1 = (X @ K.T)[:, :2] / X[:, 2:]; Xc2 = X @ R.T + [-0.1, 0.005, 0.01]; x2 = (Xc2 @ K.T)[:, :2] / Xc2[:, 2:]
    >>> y = lambda H, x: (np.c_[x, np.ones(2)] @ H.T)[:, 1] / (np.c_[x, np.ones(2)] @ H.T)[:, 2]
    >>> bool(np.abs(y(rect.H1, x1) - y(rect.H2, x2)).max() < 1e-9)
    True
    """
    K1, K2 = as_intrinsics(K1, "K1"), as_intrinsics(K2, "K2")
    R = as_rotation(R, "R")
    t = as_matrix(as_array(t, "t", "(3,)").reshape(-1), "t", (3,))
    C2 = -R.T @ t
    baseline = float(np.linalg.norm(C2))
    if baseline <= 1e-12 * max(1.0, np.abs(t).max()):
        raise ValueError("t is zero: the two cameras share a centre (no baseline), so the pair cannot be rectified")
    x = C2 / baseline
    z1 = np.array([0.0, 0.0, 1.0])
    y = np.cross(z1, x)
    if np.linalg.norm(y) < 1e-6:
        raise ValueError("the baseline is along camera 1's optical axis (forward motion): the epipole is in the image "
                         "and the pair cannot be rectified by homographies")
    y /= np.linalg.norm(y)
    R_rect = np.stack([x, y, np.cross(x, y)])
    f = 0.5 * (K1[1, 1] + K2[1, 1])
    K_new = np.array([[f, 0.0, 0.0], [0.0, f, 0.0], [0.0, 0.0, 1.0]])
    if image_size is not None:
        w, h = as_image_size(image_size)
        centre = np.array([(w - 1) / 2, (h - 1) / 2, 1.0])
        m = []
        for H in (K_new @ R_rect @ np.linalg.inv(K1), K_new @ R_rect @ R.T @ np.linalg.inv(K2)):
            q = H @ centre
            m.append(q[:2] / q[2])
        K_new[:2, 2] = centre[:2] - np.mean(m, axis=0)
    else:
        K_new[:2, 2] = 0.5 * (K1[:2, 2] + K2[:2, 2])
    H1 = K_new @ R_rect @ np.linalg.inv(K1)
    H2 = K_new @ R_rect @ R.T @ np.linalg.inv(K2)
    P1 = K_new @ np.hstack([R_rect, np.zeros((3, 1))])
    P2 = K_new @ np.hstack([R_rect, -(R_rect @ C2)[:, None]])
    return Rectification(H1=H1, H2=H2, K_new=K_new, R_rect=R_rect, P1=P1, P2=P2, baseline=baseline)


def rectify_points(x, K, dist, H):
    """Measured pixels of a camera with distortion → pixels of the rectified image: undistort, then ``H``.

    Parameters
    ----------
    x : (N, 2) array_like
    K : (3, 3) array_like
    dist : (5,) array_like
    H : (3, 3) array_like
        A rectifying homography (``Rectification.H1`` or ``H2``).

    Returns
    -------
    (N, 2) ndarray
    """
    x = as_points(x, "x", min_n=0)
    u = undistort_points(x, K, dist)
    q = np.hstack([u, np.ones((len(u), 1))]) @ as_matrix(H, "H", (3, 3)).T
    return q[:, :2] / q[:, 2:]


def rectify_image(image, K, dist, H, out_size=None):
    """Warp an image into the rectified frame: ``cv2.remap`` with the maps of :func:`remap_grid` (bilinear)."""
    image = as_image(image, "image")
    h, w = image.shape[:2]
    mx, my = remap_grid(K, dist, (w, h), H, out_size)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
