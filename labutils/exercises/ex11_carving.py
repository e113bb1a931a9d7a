"""Self-checks of notebook 11 (space carving): a silhouette from colour, the carving test of one view, the IoU."""
import numpy as np

from ..model.carving import inside_silhouette, mask_iou
from ..model.synthetic import make_snowman
from .runner import run_checks

__all__ = ["check_silhouette_from_colour", "check_carve_step", "check_mask_iou"]


# --- a silhouette from colour --------------------------------------------------------------------------------------
def _reference_silhouette(image, background, threshold):
    d = np.linalg.norm(image.astype(float) - np.asarray(background, float), axis=-1)
    return d > threshold


def _as_mask(m, shape, name):
    m = np.asarray(m)
    if m.shape != shape:
        raise ValueError(f"{name} must return a (H, W) mask of shape {shape}; it returned shape {m.shape}")
    if m.dtype != bool:
        if m.dtype.kind in "iuf" and np.isin(m, (0, 1)).all():
            return m.astype(bool)
        raise ValueError(f"{name} must return a boolean mask; it returned dtype {m.dtype}")
    return m


def _diagnose_silhouette(m, image, background, threshold):
    ref = _reference_silhouette(image, background, threshold)
    if np.array_equal(m, ref):
        return None
    img = image.astype(float)
    bg = np.asarray(background, float)
    wrapped = np.linalg.norm((image - np.asarray(background, np.uint8)).astype(float), axis=-1) > threshold
    if np.array_equal(m, ~ref):
        return "your mask is inverted: the object is where the colour is FAR from the background (distance > threshold)"
    if np.array_equal(m, wrapped):
        return ("uint8 arithmetic wraps around (10 - 200 = 66 in uint8): convert the image to float (or int) before "
                "subtracting the background colour")
    if np.array_equal(m, np.any(np.abs(img - bg) > threshold, axis=-1)):
        return ("you tested each channel separately; the distance is the Euclidean norm over the three channels: "
                "sqrt(dr² + dg² + db²) > threshold")
    if np.array_equal(m, np.linalg.norm(img - bg, axis=-1) >= threshold):
        return "a pixel exactly at the threshold is background: use '>' (strictly greater), not '>='"
    if np.array_equal(m, ((img - bg) ** 2).sum(-1) > threshold):
        return "you compared the squared distance with the threshold: take the square root (or square the threshold)"
    return (f"{np.count_nonzero(m != ref)} of {m.size} pixels differ from the expected mask: a pixel is the object "
            "when the Euclidean distance between its RGB colour and the background colour exceeds the threshold")


def check_silhouette_from_colour(silhouette_from_colour, verbose=True):
    """Self-check of ``silhouette_from_colour(image, background, threshold) -> (H, W) bool``.

    Cases: two flat colours (exact), a random image, and a dark object on a bright background (uint8 wrap-around).

    Examples
    --------
    >>> from labutils.exercises.ex11_carving import _reference_silhouette
    >>> check_silhouette_from_colour(_reference_silhouette, verbose=False).passed
    True
    """
    def run(f, image, background, threshold):
        m = _as_mask(f(image.copy(), np.array(background, np.uint8), threshold), image.shape[:2],
                     "silhouette_from_colour")
        return _diagnose_silhouette(m, image, background, threshold)

    def flat(f):
        img = np.zeros((20, 30, 3), np.uint8)
        img[:] = (40, 60, 200)
        img[5:15, 10:20] = (230, 120, 20)
        img[0, 0] = (40 + 30, 60, 200)                        # exactly at the threshold: background
        img[0, 1] = (40 + 10, 60, 200)                        # closer than the threshold: background
        return run(f, img, (40, 60, 200), 30.0)

    def noisy(f):
        rng = np.random.default_rng(11)
        img = rng.integers(0, 256, size=(24, 32, 3), dtype=np.uint8)
        return run(f, img, (90, 100, 140), 120.0)

    def dark_on_bright(f):
        img = np.zeros((16, 16, 3), np.uint8)
        img[:] = (200, 180, 60)
        img[4:12, 4:12] = (10, 20, 70)
        return run(f, img, (200, 180, 60), 50.0)

    return run_checks("silhouette_from_colour", silhouette_from_colour, [
        ("two flat colours: the square is the object, a pixel at exactly the threshold is not", flat),
        ("a random image: Euclidean RGB distance > threshold", noisy),
        ("a dark object on a bright background (no uint8 wrap-around)", dark_on_bright),
    ], verbose=verbose)


# --- the carving test of one view ----------------------------------------------------------------------------------
def _as_keep(k, n):
    k = np.asarray(k)
    if k.shape != (n,):
        raise ValueError(f"carve_step must return an (N,) boolean array for N = {n} points; it returned shape "
                         f"{k.shape}")
    if k.dtype != bool:
        raise ValueError(f"carve_step must return booleans; it returned dtype {k.dtype}")
    return k


def _variant(X, P, mask, *, swap=False, divide=True, rnd="round", bounds=True, depth=True):
    """The carving test with one typical mistake switched on."""
    x_h = X @ P[:, :3].T + P[:, 3]
    x = x_h[:, :2] / x_h[:, 2:] if divide else x_h[:, :2]
    c, r = (np.floor(x[:, 0] + 0.5), np.floor(x[:, 1] + 0.5)) if rnd == "round" else (np.trunc(x[:, 0]),
                                                                                       np.trunc(x[:, 1]))
    h, w = mask.shape
    ok = np.isfinite(c) & np.isfinite(r)
    hc, wc = (w, h) if swap else (h, w)                          # the bounds the (wrong) lookup needs
    if bounds:
        ok &= (c >= 0) & (c < wc) & (r >= 0) & (r < hc)
    else:
        ok &= (c > -wc) & (c < wc) & (r > -hc) & (r < hc)       # negative indices wrap around in numpy
    if depth:
        ok &= x_h[:, 2] > 0
    out = np.zeros(len(X), bool)
    ci, ri = c[ok].astype(int), r[ok].astype(int)
    out[ok] = mask[ci, ri] if swap else mask[ri, ci]
    return out


def _index_error_inside(f, X, P, mask):
    """Whether ``f`` raises an IndexError on an axis-0 lookup of a non-square mask even when given only the points
    that project inside the image, in front of the camera (then it indexes mask[col, row], not a bounds slip)."""
    h, w = mask.shape
    if h == w:
        return False
    x_h = X @ P[:, :3].T + P[:, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        c, r = np.floor(x_h[:, 0] / x_h[:, 2] + 0.5), np.floor(x_h[:, 1] / x_h[:, 2] + 0.5)
    inside = (x_h[:, 2] > 0) & (c >= 0) & (c < w) & (r >= 0) & (r < h)
    if not inside.any():
        return False
    try:
        f(X[inside].copy(), P.copy(), mask.copy())
    except IndexError as exc:
        return "axis 0" in str(exc)
    except Exception:                                      # any other failure: not this diagnosis
        return False
    return False


def _diagnose_carve(keep, X, P, mask):
    ref = inside_silhouette(X, P, mask)
    if np.array_equal(keep, ref):
        return None
    if np.array_equal(keep, ~ref):
        return "your test is inverted: keep the points that land INSIDE the silhouette"
    if not keep.any():
        return (f"no point survives, but {np.count_nonzero(ref)} of {len(ref)} project inside the silhouette: did you "
                "divide by w (pixels are (u / w, v / w) for P @ [X; 1] = (u, v, w)) and look up mask[row, col]?")
    tries = [
        (dict(swap=True), "you indexed the mask as mask[x, y]: rows are y, columns are x, so use mask[row, col] = "
                          "mask[y, x]"),
        (dict(divide=False), "you forgot the perspective division: pixels are (u / w, v / w) for "
                             "P @ [X; 1] = (u, v, w)"),
        (dict(rnd="trunc"), "you truncated the pixel coordinates; round to the nearest pixel (pixel centres sit at "
                            "integer coordinates: column = floor(x + 0.5))"),
        (dict(bounds=False), "points that project outside the image must be carved away; negative indices silently "
                             "wrap around to the other side of the mask in numpy"),
        (dict(depth=False), "a point behind the camera (w <= 0) projects into the image too, upside down: "
                            "carve it away"),
    ]
    for kw, hint in tries:
        try:
            if np.array_equal(keep, _variant(X, P, mask, **kw)):
                return hint
        except IndexError:
            continue
    return (f"{np.count_nonzero(keep != ref)} of {len(ref)} points are judged differently from the library's "
            "inside_silhouette: project with P, divide by w, round to the nearest pixel, look up mask[row, col]; "
            "outside the image or behind the camera means carved away")


def check_carve_step(carve_step, verbose=True):
    """Self-check of ``carve_step(X, P, mask) -> (N,) bool`` (which voxel centres survive one view).

    Cases: a synthetic snowman's voxel grid in one view (the library's ``inside_silhouette`` as reference), every
    view of it, and points outside the image or behind the camera.

    Examples
    --------
    >>> check_carve_step(inside_silhouette, verbose=False).passed
    True
    """
    scene = make_snowman(6, rng=np.random.default_rng(0), image_size=(90, 60), f=110.0)
    g = np.stack(np.meshgrid(*[np.linspace(-0.45, 0.45, 15)] * 2, np.linspace(-0.35, 0.95, 19), indexing="ij"), -1)
    X = g.reshape(-1, 3)

    def run(f, X, P, mask):
        try:
            keep = f(X.copy(), P.copy(), mask.copy())
        except IndexError as exc:
            if _index_error_inside(f, X, P, mask):        # points inside the image fail too: the lookup's order
                return (f"IndexError ({exc}) for points inside the image: index the mask as mask[row, col] = "
                        f"mask[y, x], y first (the mask is H x W = {mask.shape[0]} x {mask.shape[1]}; mask[col, row] "
                        "goes past the last row as soon as a column exceeds H - 1)")
            return (f"IndexError ({exc}): a point projects outside the image; carve it away instead of indexing the "
                    "mask (check 0 <= column < W and 0 <= row < H first)")
        return _diagnose_carve(_as_keep(keep, len(X)), X, P, mask)

    def one_view(f):
        return run(f, X, scene.P[0], scene.masks[0])

    def every_view(f):
        for P, m in zip(scene.P[1:], scene.masks[1:]):
            hint = run(f, X, P, m)
            if hint:
                return hint
        return None

    def outside(f):
        P = np.array([[100.0, 0, 40, 0], [0, 100, 30, 0], [0, 0, 1, 0]])
        mask = np.ones((60, 80), bool)
        pts = np.array([[0.0, 0, 1], [-0.6, 0, 1], [0.5, 0, 1], [0, -0.4, 1], [0, 0.35, 1],   # in; 4 outside
                        [0.1, 0.1, -1], [-0.2, -0.1, -2]])                                    # behind the camera
        return run(f, pts, P, mask)

    return run_checks("carve_step", carve_step, [
        ("a voxel grid around a snowman, one view", one_view),
        ("the same grid in five more views", every_view),
        ("points outside the image and behind the camera are carved away", outside),
    ], verbose=verbose)


# --- the IoU of two masks ------------------------------------------------------------------------------------------
def _diagnose_iou(value, a, b):
    ref = mask_iou(a, b)
    try:
        v = float(value)
    except (TypeError, ValueError):
        return f"mask_iou must return a number; it returned {type(value).__name__}"
    if abs(v - ref) < 1e-12:
        return None
    inter, na, nb = np.count_nonzero(a & b), np.count_nonzero(a), np.count_nonzero(b)
    if np.isclose(v, inter / na) or np.isclose(v, inter / nb):
        return "you divided by the area of one mask; the IoU divides by the area of the union |a ∨ b|"
    if np.isclose(v, 2 * inter / (na + nb)):
        return "that is the Dice coefficient 2|a ∧ b| / (|a| + |b|); the IoU is |a ∧ b| / |a ∨ b|"
    if np.isclose(v, inter / (na + nb)):
        return "|a| + |b| counts the intersection twice: the union is |a| + |b| - |a ∧ b| (or count a | b)"
    if np.isclose(v, inter):
        return "divide the intersection by the union's area"
    return f"expected IoU {ref:.6f}; got {v:.6f}: intersection |a ∧ b| over union |a ∨ b|, counted in pixels"


def check_mask_iou(iou, verbose=True):
    """Self-check of ``mask_iou(a, b) -> float`` (intersection over union of two boolean masks).

    Cases: two overlapping rectangles (exact), random masks, identical and disjoint masks, and two empty masks
    (the IoU is undefined: raise ``ValueError``).

    Examples
    --------
    >>> check_mask_iou(mask_iou, verbose=False).passed
    True
    """
    def rects(f):
        a = np.zeros((10, 20), bool)
        b = np.zeros((10, 20), bool)
        a[2:8, 2:12] = True
        b[4:10, 6:18] = True
        return _diagnose_iou(f(a.copy(), b.copy()), a, b)

    def random(f):
        rng = np.random.default_rng(7)
        a, b = rng.random((30, 40)) < 0.3, rng.random((30, 40)) < 0.6
        return _diagnose_iou(f(a.copy(), b.copy()), a, b)

    def extremes(f):
        a = np.zeros((5, 5), bool)
        a[1:3, 1:4] = True
        b = np.zeros((5, 5), bool)
        b[4, 4] = True
        for x, y, want in ((a, a, 1.0), (a, b, 0.0)):
            v = f(x.copy(), y.copy())
            if not np.isclose(float(v), want):
                return f"{'identical' if want else 'disjoint'} masks have IoU {want:g}; got {v}"
        return None

    def empty(f):
        z = np.zeros((4, 4), bool)
        try:
            v = f(z, z.copy())
        except ValueError:
            return None
        except ZeroDivisionError:
            return "two empty masks raised ZeroDivisionError: check for an empty union and raise a ValueError saying so"
        return (f"two empty masks returned {v}: their IoU is 0/0, undefined; raise a ValueError rather than return "
                "a number (or NaN) that looks like an answer")

    return run_checks("mask_iou", iou, [
        ("two overlapping rectangles", rects),
        ("two random masks", random),
        ("identical masks give 1, disjoint masks 0", extremes),
        ("two empty masks: ValueError (undefined), not NaN", empty),
    ], verbose=verbose)
