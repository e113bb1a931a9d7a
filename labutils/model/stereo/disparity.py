"""Disparity of a rectified pair by a plane sweep with a ZNCC cost, and the left–right consistency check.

In a rectified pair (:mod:`labutils.calibrate.rectification`) the match of left pixel ``(x, y)`` lies on the same row
of the right image, at ``(x - d, y)``: ``d`` is the *disparity*. A fronto-parallel plane at depth ``Z`` in the rectified
frame is a constant disparity ``d = f b / Z``, so sweeping ``d`` over a range is sweeping a plane through the scene
(Collins 1996; Szeliski, *Computer Vision*, 2nd ed., Sec. 12.1 and 12.4). For every ``d`` we score every pixel by
the **zero-mean normalised cross-correlation** (ZNCC) of the window around it with the window around its candidate
match (Szeliski Sec. 12.3; Hirschmüller & Scharstein, PAMI 2009, compare costs),

    ZNCC = (mean(L R) - mean(L) mean(R)) / (std(L) std(R))        in [-1, 1],

which does not change when either window's brightness is scaled or offset (a gain and a bias between the cameras).
Each mean over a window is a **box filter**, computed for all pixels at once from an integral image (Crow 1984;
Viola & Jones 2001), so one disparity costs a handful of whole-image operations whatever the window's size. The
disparity of a pixel is the sweep's best score (winner takes all), refined to a fraction of a pixel by a parabola
through the costs at ``d - 1, d, d + 1``.

Why a plane sweep and not PatchMatch (Bleyer, Rhemann & Rother, BMVC 2011): with known cameras and a known box
around the object the disparity range is short (tens of values), an exhaustive sweep is exact (no random start, no
propagation order), deterministic, and vectorises over the image in numpy; PatchMatch pays off for slanted windows
and wide ranges, but its propagation is a sequential scan that Python runs slowly.

The **left–right check** (Fua 1993; Egnal & Wildes, PAMI 2002) computes the disparity a second time with the right
image as reference and keeps a left pixel only if its match maps back to it: a pixel of the left image that the
right camera does not see (an occlusion) has no true match, its best score lands on another surface, and that
surface's pixel in the right image points back elsewhere.

Conventions: images are rectified, ``(h, w)`` grey or ``(h, w, 3)`` RGB (grey levels 0..255); a disparity is
``d = x_left - x_right`` in both the left- and the right-referenced map; NaN marks a pixel without a valid disparity.
"""
import numpy as np
from numpy.typing import ArrayLike

from ...core.validation import as_array, as_positive

__all__ = ["as_grey", "box_mean", "zncc", "zncc_volume", "disparity_plane_sweep", "left_right_check"]


def as_grey(image: ArrayLike, name: str = "image") -> np.ndarray:
    """A float ``(h, w)`` grey image from a ``(h, w)`` grey or ``(h, w, 3)`` RGB array (ITU-R BT.601 weights).

    >>> as_grey(np.full((2, 3, 3), 100, np.uint8)).tolist()[0]
    [100.0, 100.0, 100.0]
    >>> as_grey(np.zeros((4, 3)).T[None])
    Traceback (most recent call last):
    ...
    ValueError: image must be an (h, w) grey or (h, w, 3) RGB image; got shape (1, 3, 4)
    """
    try:
        a = as_array(image, name, "(h, w) or (h, w, 3)")
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an (h, w) grey or (h, w, 3) RGB image (numeric)") from None
    if a.ndim == 3 and a.shape[2] == 3:
        a = a @ np.array([0.299, 0.587, 0.114])
    if a.ndim != 2:
        raise ValueError(f"{name} must be an (h, w) grey or (h, w, 3) RGB image; got shape {np.shape(image)}")
    if min(a.shape) < 1:
        raise ValueError(f"{name} is empty; got shape {np.shape(image)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has non-finite values (NaN or inf)")
    return a


def _as_radius(window):
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1 or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 1 (the side of the square window, pixels); got {window!r}")
    return int(window) // 2


def box_mean(image: ArrayLike, window: int) -> np.ndarray:
    """The mean of every ``window × window`` square of an image, from its integral image.

    With the integral image ``S[i, j] = Σ_{r < i, c < j} I[r, c]`` (one row and column of zeros in front), the sum
    over rows ``y - k .. y + k`` and columns ``x - k .. x + k`` is ``S[y+k+1, x+k+1] - S[y-k, x+k+1] - S[y+k+1, x-k]
    + S[y-k, x-k]``: four look-ups per pixel, whatever the window's size.

    Parameters
    ----------
    image : (h, w) array_like
    window : int
        Odd side of the square, ``2k + 1``.

    Returns
    -------
    (h, w) float ndarray
        NaN where the window does not fit inside the image (``k`` pixels along each border).

    Examples
    --------
    >>> box_mean(np.arange(16.0).reshape(4, 4), 3)
    array([[nan, nan, nan, nan],
           [nan,  5.,  6., nan],
           [nan,  9., 10., nan],
           [nan, nan, nan, nan]])
    """
    k = _as_radius(window)
    try:
        a = as_array(image, "image", "(h, w)")
    except (TypeError, ValueError):
        raise ValueError("image must be a numeric (h, w) array") from None
    if a.ndim != 2:
        raise ValueError(f"image must have shape (h, w); got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("image has non-finite values (NaN or inf): they would spread through the integral image")
    h, w = a.shape
    out = np.full((h, w), np.nan)
    if h < window or w < window:
        return out
    S = np.zeros((h + 1, w + 1))
    S[1:, 1:] = a.cumsum(axis=0).cumsum(axis=1)
    n = window
    out[k:h - k, k:w - k] = (S[n:, n:] - S[:-n, n:] - S[n:, :-n] + S[:-n, :-n]) / (n * n)
    return out


def zncc(patch1: ArrayLike, patch2: ArrayLike) -> float:
    """The zero-mean normalised cross-correlation of two windows of the same shape.

    ``Σ (a - ā)(b - b̄) / sqrt(Σ (a - ā)² Σ (b - b̄)²)``: 1 for windows equal up to a gain and a bias, -1 for a
    negative, near 0 for unrelated texture.

    Raises
    ------
    ValueError
        If the shapes differ, a value is not finite, or a window is constant (ZNCC is 0/0, undefined).

    Examples
    --------
    >>> a = np.array([[1.0, 2.0], [3.0, 5.0]])
    >>> round(zncc(a, 3 * a + 7), 12), round(zncc(a, -a), 12)
    (1.0, -1.0)
    """
    try:
        a, b = as_array(patch1, "patch1", "(h, w)"), as_array(patch2, "patch2", "(h, w)")
    except (TypeError, ValueError):
        raise ValueError("patch1 and patch2 must be numeric arrays of the same shape") from None
    if a.shape != b.shape or a.size < 2:
        raise ValueError(f"patch1 and patch2 must have the same shape with at least 2 pixels; got {a.shape} and "
                         f"{b.shape}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("patch1 and patch2 must be finite (no NaN or inf)")
    a, b = a - a.mean(), b - b.mean()
    den = np.sqrt((a * a).sum() * (b * b).sum())
    if den <= 1e-12 * max(1.0, np.abs(a).max() * np.abs(b).max()) * a.size:
        raise ValueError("a window is constant: its ZNCC is 0/0, undefined (no texture to match)")
    return float((a * b).sum() / den)


def _as_pair(left, right):
    L, R = as_grey(left, "left"), as_grey(right, "right")
    if L.shape != R.shape:
        raise ValueError(f"left and right must have the same size (a rectified pair); got {L.shape} and {R.shape}")
    return L, R


def _as_disparities(disparities):
    try:
        d = np.asarray(disparities)
    except (TypeError, ValueError):
        d = np.array([])
    if d.ndim != 1 or d.size == 0 or d.dtype.kind not in "iu":
        raise ValueError(f"disparities must be a non-empty 1-D array of integers (pixels); got {disparities!r}")
    return d.astype(int)


def _zncc_slices(L, R, disparities, window, min_std):
    """Yield the ZNCC map for each disparity: ``z[y, x]`` compares left ``(x, y)`` with right ``(x - d, y)``."""
    k = window // 2
    h, w = L.shape
    muL, muR = box_mean(L, window), box_mean(R, window)
    sdL = np.sqrt(np.maximum(box_mean(L * L, window) - muL ** 2, 0.0))
    sdR = np.sqrt(np.maximum(box_mean(R * R, window) - muR ** 2, 0.0))
    # textureless windows get no score: below min_std, and always where the variance is only rounding error
    sdL[~(sdL >= min_std) | (sdL <= 1e-6 * (np.abs(muL) + 1))] = np.nan
    sdR[~(sdR >= min_std) | (sdR <= 1e-6 * (np.abs(muR) + 1))] = np.nan
    for d in disparities:
        x0, x1 = max(d, 0), min(w, w + d)                 # columns x whose x - d is in the image
        z = np.full((h, w), np.nan)
        if x1 - x0 >= window:
            prod = np.zeros((h, w))
            prod[:, x0:x1] = L[:, x0:x1] * R[:, x0 - d:x1 - d]
            m = box_mean(prod, window)
            c = slice(x0 + k, x1 - k)                     # the whole window (and its match's) inside
            cr = slice(x0 + k - d, x1 - k - d)
            z[:, c] = (m[:, c] - muL[:, c] * muR[:, cr]) / (sdL[:, c] * sdR[:, cr])
        yield np.clip(z, -1.0, 1.0)


def zncc_volume(left: ArrayLike, right: ArrayLike, disparities: ArrayLike, window: int = 9, *,
                min_std: float = 1.0) -> np.ndarray:
    """The ZNCC of every left pixel's window with its candidate match at every disparity: the sweep's score volume.

    Parameters
    ----------
    left, right : (h, w) or (h, w, 3) array_like
        A rectified pair.
    disparities : (D,) array_like of int
        Candidate disparities ``d = x_left - x_right``, pixels.
    window : int
        Odd side of the square window.
    min_std : float
        A window whose grey levels vary less than this (standard deviation, grey levels) has no texture to match:
        its score is NaN.

    Returns
    -------
    (D, h, w) float32 ndarray
        ``volume[k, y, x]`` compares left ``(x, y)`` with right ``(x - disparities[k], y)``; NaN where either window
        leaves its image or is textureless.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> right = rng.uniform(0, 255, (20, 40)); left = np.roll(right, 3, axis=1)      # left(x) = right(x - 3)
    >>> v = zncc_volume(left, right, [2, 3, 4], window=5)
    >>> [round(float(np.nanmean(s)), 1) for s in v[:, :, 10:30]]
    [-0.1, 1.0, -0.1]
    """
    L, R = _as_pair(left, right)
    ds = _as_disparities(disparities)
    _as_radius(window)
    min_std = as_positive(min_std, "min_std", allow_zero=True)
    return np.stack([z.astype(np.float32) for z in _zncc_slices(L, R, ds, window, min_std)])


def disparity_plane_sweep(left: ArrayLike, right: ArrayLike, d_min: int, d_max: int, *, window: int = 9,
                          min_zncc: float = 0.5, min_std: float = 2.0, reference: str = "left") -> np.ndarray:
    """Disparity map of a rectified pair: sweep ``d = d_min .. d_max``, keep each pixel's best ZNCC, refine it.

    For each pixel the integer disparity with the highest ZNCC wins; the cost ``c = 1 - ZNCC`` at ``d - 1, d, d + 1``
    is fitted by a parabola, whose minimum ``d + (c₋ - c₊) / (2 (c₋ - 2 c₀ + c₊))`` is the sub-pixel disparity.
    A pixel gets NaN when its window is textureless, its best ZNCC is below ``min_zncc``, or the best lies at either
    end of the range (the true disparity may lie outside it).

    Parameters
    ----------
    left, right : (h, w) or (h, w, 3) array_like
        A rectified pair (matches on the same row, ``x_right = x_left - d``).
    d_min, d_max : int
        The disparity range swept, ``d_min < d_max`` (may be negative).
    window : int
        Odd side of the square window, pixels.
    min_zncc : float
        Lowest accepted score, in (-1, 1].
    min_std : float
        Lowest accepted standard deviation of a window's grey levels (texture).
    reference : {'left', 'right'}
        Whose pixels the map is on. ``'right'``: ``disparity[y, x_r]`` is ``x_l - x_r`` of the right pixel's match
        (the same sign as the left map), for the left–right check.

    Returns
    -------
    (h, w) float ndarray
        Disparity ``x_left - x_right`` in pixels, NaN where there is no valid disparity.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> right = rng.uniform(0, 255, (30, 60)); left = np.roll(right, 7, axis=1)
    >>> d = disparity_plane_sweep(left, right, 0, 12, window=5)
    >>> inner = d[2:-2, 10:-2]                 # windows inside both images at d = 6, 7, 8
    >>> bool(np.all(np.abs(inner - 7) < 0.2))
    True
    """
    L, R = _as_pair(left, right)
    k = _as_radius(window)
    if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (d_min, d_max)) or d_max <= d_min:
        raise ValueError(f"d_min and d_max must be integers with d_min < d_max; got {d_min!r} and {d_max!r}")
    if not (isinstance(min_zncc, (int, float, np.floating)) and -1 < float(min_zncc) <= 1):
        raise ValueError(f"min_zncc must be a number in (-1, 1]; got {min_zncc!r}")
    min_std = as_positive(min_std, "min_std", allow_zero=True)
    if reference not in ("left", "right"):
        raise ValueError(f"reference must be 'left' or 'right'; got {reference!r}")
    if reference == "right":       # mirror both images: the right image becomes a left reference, same disparities
        return disparity_plane_sweep(R[:, ::-1], L[:, ::-1], d_min, d_max, window=2 * k + 1, min_zncc=min_zncc,
                                     min_std=min_std)[:, ::-1].copy()
    ds = np.arange(int(d_min), int(d_max) + 1)
    h, w = L.shape
    best = np.full((h, w), -np.inf)
    best_k = np.full((h, w), -1)
    before = np.full((h, w), np.nan)                    # ZNCC at the best d - 1 and d + 1
    after = np.full((h, w), np.nan)
    prev = np.full((h, w), np.nan)
    for i, z in enumerate(_zncc_slices(L, R, ds, 2 * k + 1, min_std)):
        after[best_k == i - 1] = z[best_k == i - 1]
        better = z > best                               # NaN compares False: never wins
        best[better], best_k[better], before[better] = z[better], i, prev[better]
        prev = z
    ok = (best_k > 0) & (best_k < len(ds) - 1) & (best >= min_zncc)
    c_m, c_0, c_p = 1 - before, 1 - best, 1 - after
    curv = c_m - 2 * c_0 + c_p
    ok &= np.isfinite(c_m) & np.isfinite(c_p) & (curv > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = np.clip(0.5 * (c_m - c_p) / curv, -0.5, 0.5)
    disparity = np.full((h, w), np.nan)
    disparity[ok] = ds[best_k[ok]] + delta[ok]
    return disparity


def _as_disparity_map(d, name):
    a = as_array(d, name, "(h, w) (NaN where invalid)")
    if a.ndim != 2:
        raise ValueError(f"{name} must be an (h, w) disparity map (NaN where invalid); got shape {a.shape}")
    if np.isinf(a).any():
        raise ValueError(f"{name} has infinite values: mark a pixel without a disparity with NaN")
    return a


def left_right_check(d_left: ArrayLike, d_right: ArrayLike, threshold_px: float = 1.0) -> np.ndarray:
    """Which left pixels pass the left–right consistency check.

    Left pixel ``(x, y)`` with disparity ``d`` matches right pixel ``(x_r, y)``, ``x_r = round(x - d)``; it is
    consistent when the right map's disparity there is finite and within ``threshold_px`` of ``d``:
    ``|d_left[y, x] - d_right[y, x_r]| <= threshold_px``.

    Parameters
    ----------
    d_left, d_right : (h, w) array_like
        Disparity maps referenced on the left and on the right image (both ``x_left - x_right``), NaN where invalid.
    threshold_px : float
        Largest accepted disagreement, pixels.

    Returns
    -------
    (h, w) bool ndarray
        False where ``d_left`` is NaN, the match falls outside the right image, or the two disagree.

    Examples
    --------
    >>> dl = np.array([[2.0, 2.0, 2.0, 2.0, 2.0]]); dr = np.array([[2.0, 2.0, 5.0, np.nan, np.nan]])
    >>> left_right_check(dl, dr).tolist()                  # x = 2, 3, 4 match x_r = 0, 1, 2
    [[False, False, True, True, False]]
    """
    dl, dr = _as_disparity_map(d_left, "d_left"), _as_disparity_map(d_right, "d_right")
    if dl.shape != dr.shape:
        raise ValueError(f"d_left and d_right must have the same shape; got {dl.shape} and {dr.shape}")
    threshold_px = as_positive(threshold_px, "threshold_px", allow_zero=True)
    h, w = dl.shape
    ys, xs = np.nonzero(np.isfinite(dl))
    xr = np.floor(xs - dl[ys, xs] + 0.5).astype(int)
    inside = (xr >= 0) & (xr < w)
    ok = np.zeros((h, w), bool)
    ys, xs, xr = ys[inside], xs[inside], xr[inside]
    with np.errstate(invalid="ignore"):
        ok[ys, xs] = np.abs(dl[ys, xs] - dr[ys, xr]) <= threshold_px
    return ok
