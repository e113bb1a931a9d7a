"""Self-checks of notebook 12 (dense stereo): the ZNCC of two windows, the left–right check, disparity → 3D points.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (no mean subtraction, the match looked up at ``x + d``,
truncating instead of rounding, the principal point forgotten ...).
"""
import numpy as np

from ..model.stereo import left_right_check, zncc
from ..model.stereo.synthetic import make_layered_pair
from ..twoview.triangulation import triangulate
from .runner import run_checks

__all__ = ["check_zncc_patch", "check_left_right_consistent", "check_points_from_disparity"]


# ---------------------------------------------------------------------------------------------------------------
# exercise 1: the ZNCC of two windows
# ---------------------------------------------------------------------------------------------------------------
def _as_score(value, name="zncc_patch"):
    try:
        v = float(np.asarray(value).reshape(()))
    except (TypeError, ValueError):
        raise ValueError(f"{name} must return one number; it returned {type(value).__name__} "
                         f"{np.shape(value)}") from None
    return v


def _diagnose_zncc(v, a, b):
    """None when ``v`` is the ZNCC of windows a and b, else the most likely mistake."""
    ref = zncc(a, b)
    if abs(v - ref) < 1e-9:
        return None
    if not np.isfinite(v):
        return f"your score is {v}: for two textured windows the ZNCC is a finite number in [-1, 1]"
    af, bf = a.astype(float), b.astype(float)
    da, db = af - af.mean(), bf - bf.mean()
    n = a.size
    variants = [
        (1 - ref, "you returned the cost 1 - ZNCC; return the score itself (1 for a perfect match)"),
        ((af * bf).sum() / np.sqrt((af * af).sum() * (bf * bf).sum()),
         "you did not subtract each window's mean first: that is NCC, which a change of brightness (a bias) "
         "changes; ZNCC uses a - mean(a) and b - mean(b)"),
        ((da * db).sum(), "divide by the norms of the two zero-mean windows: sqrt(Σ(a-ā)² · Σ(b-b̄)²)"),
        ((da * db).mean(), "that is the covariance; divide it by the two standard deviations"),
        ((da * db).sum() / (n * a.std(ddof=1) * b.std(ddof=1)),
         "the sums and the standard deviations disagree by (n - 1)/n: use the same normalisation (e.g. np.std with "
         "its default ddof=0, or sums throughout)"),
        ((da * db).sum() / ((da * da).sum() * (db * db).sum()), "take the square root of the product of the sums "
                                                                 "of squares"),
        (ref ** 2, "you squared the score (or took its absolute value): a negative correlation (an inverted window) "
                   "must stay negative"),
        (abs(ref), "you took the absolute value (or squared the score): a negative correlation (an inverted window) "
                   "must stay negative"),
    ]
    for value, hint in variants:
        if np.isfinite(value) and abs(v - value) < 1e-9:
            return hint
    if a.dtype == np.uint8:
        return ("with uint8 windows your score is wrong: uint8 arithmetic wraps around (200 * 2 = 144); convert "
                "the windows to float first")
    return (f"expected {ref:.6f}, got {v:.6f}: ZNCC = Σ(a - ā)(b - b̄) / sqrt(Σ(a - ā)² Σ(b - b̄)²), with ā, b̄ the "
            "windows' means")


def check_zncc_patch(zncc_patch, verbose=True):
    """Self-check of ``zncc_patch(patch1, patch2) -> float``.

    Cases: windows equal up to a gain and a bias (score 1), an inverted window (-1), random windows, uint8 windows
    (no wrap-around), and a constant window (undefined: ``ValueError``).

    Examples
    --------
    >>> check_zncc_patch(zncc, verbose=False).passed
    True
    """
    rng = np.random.default_rng(12)
    a = rng.uniform(0, 255, (7, 7))

    def run(f, x, y):
        return _diagnose_zncc(_as_score(f(x.copy(), y.copy())), x, y)

    def gain_bias(f):
        return run(f, a, 0.5 * a + 40.0)

    def inverted(f):
        return run(f, a, 300.0 - 2.0 * a)

    def random(f):
        for _ in range(3):
            hint = run(f, rng.uniform(0, 255, (5, 9)), rng.uniform(0, 255, (5, 9)))
            if hint:
                return hint
        return run(f, a, a + rng.normal(0, 20, a.shape))

    def uint8(f):
        x = rng.integers(0, 256, (9, 9)).astype(np.uint8)
        y = np.clip(x.astype(int) // 2 + 100 + rng.integers(-20, 21, x.shape), 0, 255).astype(np.uint8)
        return run(f, x, y)

    def constant(f):
        try:
            with np.errstate(all="ignore"):
                v = f(np.full((5, 5), 80.0), a[:5, :5].copy())
        except ValueError:
            return None
        except ZeroDivisionError:
            return "a constant window raised ZeroDivisionError: check for zero variance and raise a ValueError"
        return (f"a constant window returned {v}: its ZNCC is 0/0, undefined (no texture to match); raise a "
                "ValueError instead of returning a number or NaN")

    return run_checks("zncc_patch", zncc_patch, [
        ("windows equal up to a gain and a bias score 1", gain_bias),
        ("an inverted window scores -1", inverted),
        ("random windows", random),
        ("uint8 windows (no wrap-around)", uint8),
        ("a constant window: ValueError (0/0), not NaN", constant),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: the left–right check
# ---------------------------------------------------------------------------------------------------------------
def _as_keep(k, shape, name="left_right_consistent"):
    k = np.asarray(k)
    if k.shape != shape:
        raise ValueError(f"{name} must return an (h, w) mask of shape {shape}; it returned shape {k.shape}")
    if k.dtype != bool:
        raise ValueError(f"{name} must return booleans; it returned dtype {k.dtype}")
    return k


def _lr_variant(dl, dr, t, *, sign=-1, rnd="round", strict=False, bounds=True, nan_passes=False, same_pixel=False):
    """The left–right check with one typical mistake switched on."""
    h, w = dl.shape
    ys, xs = np.mgrid[0:h, 0:w]
    with np.errstate(invalid="ignore"):
        xr_f = xs + sign * dl
        xr = np.floor(xr_f + 0.5) if rnd == "round" else np.trunc(xr_f)
    xr = np.where(np.isfinite(xr), xr, 0).astype(int)
    if same_pixel:
        xr = xs
    inside = (xr >= 0) & (xr < w) if bounds else (xr > -w) & (xr < w)
    other = np.full((h, w), np.nan)
    other[inside] = dr[ys[inside], xr[inside]]
    with np.errstate(invalid="ignore"):
        diff = np.abs(dl - other)
        ok = (diff < t) if strict else (diff <= t)
        if nan_passes:
            ok = ~(diff > t)
    return ok & (inside | (not bounds)) & (np.isfinite(dl) | nan_passes)


def _diagnose_lr(keep, dl, dr, t):
    ref = left_right_check(dl, dr, t)
    if np.array_equal(keep, ref):
        return None
    if np.array_equal(keep, ~ref):
        return "your mask is inverted: True means the pixel PASSES the check (its match maps back to it)"
    tries = [
        (dict(sign=+1), "the match of left pixel x is at x - d in the right image (d = x_left - x_right), not x + d"),
        (dict(same_pixel=True), "you compared d_left and d_right at the same pixel; look d_right up at the match, "
                                "x_r = round(x - d_left)"),
        (dict(rnd="trunc"), "you truncated x - d; round to the nearest pixel (floor(x - d + 0.5))"),
        (dict(strict=True), "a disagreement of exactly threshold_px passes: use <=, not <"),
        (dict(nan_passes=True), "a pixel without a disparity (NaN) must fail the check; NaN compares False, so "
                                "'not (diff > t)' lets it through"),
        (dict(bounds=False), "a match outside the right image (x - d < 0) must fail; negative indices silently "
                             "wrap around to the other side in numpy"),
    ]
    for kw, hint in tries:
        try:
            if np.array_equal(keep, _lr_variant(dl, dr, t, **kw)):
                return hint
        except IndexError:
            continue
    return (f"{np.count_nonzero(keep != ref)} of {keep.size} pixels differ from the expected mask: for each left "
            "pixel with a disparity d, look up d_right at (round(x - d), y) and keep it when the two differ by at "
            "most threshold_px; NaN or outside the image fails")


def check_left_right_consistent(left_right_consistent, verbose=True):
    """Self-check of ``left_right_consistent(d_left, d_right, threshold_px) -> (h, w) bool``.

    Cases: one row by hand, the exact disparities of a layered scene (the check must find exactly the occluded
    pixels), and noisy sub-pixel disparities with NaN holes (against the library's ``left_right_check``).

    Examples
    --------
    >>> check_left_right_consistent(left_right_check, verbose=False).passed
    True
    """
    scene = make_layered_pair(rng=np.random.default_rng(5), image_size=(64, 40), d_background=2, d_layers=(9,))

    def run(f, dl, dr, t):
        try:
            keep = f(dl.copy(), dr.copy(), t)
        except IndexError as exc:
            return (f"IndexError ({exc}): a match falls outside the right image; fail that pixel instead of indexing "
                    "(check 0 <= x_r < w first)")
        return _diagnose_lr(_as_keep(keep, dl.shape), dl, dr, t)

    def by_hand(f):
        dl = np.array([[2.0, 2.0, 2.0, 3.0, 2.4, 1.0, np.nan, 2.0]])
        dr = np.array([[2.0, 2.0, 3.5, 5.0, 1.0, np.nan, 2.5, 9.0]])   # left x = 3 is off by exactly 1.0: passes
        return run(f, dl, dr, 1.0)

    def layered(f):
        keep = f(scene.disparity_left.copy(), scene.disparity_right.copy(), 0.5)
        keep = _as_keep(keep, scene.disparity_left.shape)
        if np.array_equal(keep, ~scene.occluded_left):
            return None
        return _diagnose_lr(keep, scene.disparity_left, scene.disparity_right, 0.5) or (
            "with exact disparities the check must fail exactly the occluded pixels")

    def noisy(f):
        rng = np.random.default_rng(8)
        dl = scene.disparity_left + rng.uniform(-0.6, 0.6, scene.disparity_left.shape)
        dr = scene.disparity_right + rng.uniform(-0.6, 0.6, scene.disparity_right.shape)
        dl[rng.random(dl.shape) < 0.1] = np.nan
        dr[rng.random(dr.shape) < 0.1] = np.nan
        return run(f, dl, dr, 1.0)

    return run_checks("left_right_consistent", left_right_consistent, [
        ("one row by hand: NaN, out of the image, a disagreement at exactly the threshold", by_hand),
        ("exact disparities of a layered scene: exactly the occluded pixels fail", layered),
        ("noisy sub-pixel disparities with holes", noisy),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 3: disparity -> 3D points
# ---------------------------------------------------------------------------------------------------------------
def reference_points_from_disparity(disparity, K, baseline):
    """The library's answer (closed form): ``Z = f b / d``, ``X = Z K⁻¹ (x, y, 1)`` for the finite disparities."""
    ys, xs = np.nonzero(np.isfinite(disparity))
    Z = K[0, 0] * baseline / disparity[ys, xs]
    return np.stack([(xs - K[0, 2]) * Z / K[0, 0], (ys - K[1, 2]) * Z / K[1, 1], Z], axis=1)


def _as_X(X, n, name="points_from_disparity"):
    X = np.asarray(X, float)
    if X.shape != (n, 3):
        hint = " — transposed? points are rows" if X.shape == (3, n) else ""
        raise ValueError(f"{name} must return an (N, 3) array for the N = {n} finite disparities; it returned shape "
                         f"{X.shape}{hint}")
    return X


def _diagnose_points(X, disparity, K, b):
    ref = reference_points_from_disparity(disparity, K, b)
    X = _as_X(X, len(ref))
    scale = np.abs(ref).max()
    if np.abs(X - ref).max() <= 1e-9 * scale:
        return None
    ys, xs = np.nonzero(np.isfinite(disparity))
    d = disparity[ys, xs]
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    Z = f * b / d
    variants = [
        (-ref, "every point is behind the camera: d = x1 - x2 > 0 and Z = f b / d > 0 (did you use x2 - x1?)"),
        (ref / f, "Z = f b / d: you left out the focal length f"),
        (np.stack([xs * Z / f, ys * Z / f, Z], 1), "you forgot the principal point: X = (x - cx) Z / f, "
                                                   "Y = (y - cy) Z / f"),
        (np.stack([(ys - cx) * Z / f, (xs - cy) * Z / f, Z], 1), "x is the column and y the row: np.nonzero gives "
                                                                 "(rows, columns) = (y, x)"),
        (np.stack([(xs - cx) * d / f, (ys - cy) * d / f, d], 1), "you used the disparity as the depth; Z = f b / d"),
        (np.stack([(xs - cx) / f, (ys - cy) / f, np.ones_like(d)], 1) * (f * d / b)[:, None],
         "Z = f b / d, not f d / b: a larger disparity is a nearer point"),
        (np.stack([(xs - cx) / Z, (ys - cy) / Z, Z], 1), "X = (x - cx) Z / f: multiply by the depth and divide by f"),
    ]
    for V, hint in variants:
        if V.shape == X.shape and np.abs(X - V).max() <= 1e-6 * max(np.abs(V).max(), 1e-12):
            return hint
    if np.allclose(np.sort(X, axis=0), np.sort(ref, axis=0), rtol=1e-9, atol=1e-9 * scale):
        return "the points are right but not in the order of np.nonzero(np.isfinite(disparity)) (row by row)"
    return (f"the points differ from the triangulation by up to {np.abs(X - ref).max():.3g}: Z = f b / d, then "
            "X = (x - cx) Z / f, Y = (y - cy) Z / f for each pixel (x, y) with a finite disparity, row by row")


def check_points_from_disparity(points_from_disparity, verbose=True):
    """Self-check of ``points_from_disparity(disparity, K, baseline) -> (N, 3)`` (rectified camera 1's frame).

    Cases: a few pixels by hand, a random disparity map against the DLT triangulation of ``(x, y) ↔ (x - d, y)``
    with the rectified cameras ``K [I | 0]`` and ``K [I | -(b, 0, 0)]``, and a map with no valid pixel.

    Examples
    --------
    >>> check_points_from_disparity(reference_points_from_disparity, verbose=False).passed
    True
    """
    K = np.array([[400.0, 0.0, 161.5], [0.0, 400.0, 118.0], [0.0, 0.0, 1.0]])
    b = 0.12

    def run(f, disparity):
        return _diagnose_points(f(disparity.copy(), K.copy(), b), disparity, K, b)

    def by_hand(f):
        d = np.full((5, 6), np.nan)
        d[1, 2], d[3, 5], d[4, 0], d[4, 1] = 40.0, 24.0, 60.0, 30.0
        return run(f, d)

    def triangulated(f):
        rng = np.random.default_rng(3)
        d = rng.uniform(20, 60, (24, 32))
        d[rng.random(d.shape) < 0.3] = np.nan
        hint = run(f, d)
        if hint:
            return hint
        ys, xs = np.nonzero(np.isfinite(d))
        x1 = np.stack([xs, ys], 1).astype(float)
        x2 = x1 - np.stack([d[ys, xs], np.zeros(len(xs))], 1)
        P1 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
        P2 = K @ np.hstack([np.eye(3), [[-b], [0.0], [0.0]]])
        X = _as_X(f(d.copy(), K.copy(), b), len(xs))
        err = np.abs(X - triangulate(P1, P2, x1, x2)).max()
        return None if err < 1e-9 else f"your points differ from the DLT triangulation by {err:.3g}"

    def empty(f):
        X = np.asarray(f(np.full((4, 4), np.nan), K.copy(), b), float)
        return None if X.shape == (0, 3) else (f"a map without a valid disparity has no point: return an (0, 3) array; "
                                               f"got shape {X.shape}")

    return run_checks("points_from_disparity", points_from_disparity, [
        ("four pixels by hand", by_hand),
        ("a random map, against the DLT triangulation of (x, y) <-> (x - d, y)", triangulated),
        ("no valid disparity: an (0, 3) array", empty),
    ], verbose=verbose)
