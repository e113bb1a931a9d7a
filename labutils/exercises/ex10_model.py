"""Self-checks of notebook 10 (points, meshes, texture): the PCA normal of a neighbourhood, its orientation by
visibility, and the most frontal view of a vertex."""
import numpy as np

from ..model.texturing import most_frontal_view
from .runner import run_checks

__all__ = ["check_pca_normal", "check_orient_normal", "check_most_frontal_view"]


def _unit(v):
    return v / np.linalg.norm(v)


# --- the PCA normal of a neighbourhood -----------------------------------------------------------------------------
def _reference_pca_normal(P):
    Q = P - P.mean(axis=0)
    w, v = np.linalg.eigh(Q.T @ Q)
    return v[:, 0]


def _as_normal(n, name="pca_normal"):
    n = np.asarray(n, dtype=float)
    if n.shape != (3,):
        raise ValueError(f"{name} must return a (3,) vector; it returned shape {n.shape}")
    return n


def _diagnose_pca(n, P):
    ref = _reference_pca_normal(P)
    length = np.linalg.norm(n)
    if length == 0 or not np.isfinite(length):
        return f"your normal has length {length}: return a unit vector"
    if abs(abs(n @ ref) / length - 1) < 1e-6:
        return None if abs(length - 1) < 1e-6 else f"the direction is right but the length is {length:.4g}: normalise"
    Q = P - P.mean(axis=0)
    w, v = np.linalg.eigh(Q.T @ Q)
    if abs(abs(_unit(n) @ v[:, 2]) - 1) < 1e-6:
        return ("that is the direction of the LARGEST spread: the normal is the eigenvector of the smallest "
                "eigenvalue (np.linalg.eigh sorts them ascending: column 0)")
    if any(abs(abs(_unit(n) @ _unit(v[k])) - 1) < 1e-6 for k in range(3)):
        return "you took a row of the eigenvector matrix: np.linalg.eigh returns the eigenvectors as COLUMNS, v[:, 0]"
    w0, v0 = np.linalg.eigh(P.T @ P)
    if abs(abs(_unit(n) @ v0[:, 0]) - 1) < 1e-6 or abs(abs(_unit(n) @ np.linalg.svd(P)[2][-1]) - 1) < 1e-6:
        return ("you did not centre the points: subtract their mean before the covariance (or the SVD); otherwise "
                "the plane is forced through the origin")
    return (f"your normal is {np.degrees(np.arccos(min(1.0, abs(_unit(n) @ ref)))):.1f}° off the expected one: centre "
            "the points, form the 3x3 covariance, take the eigenvector of the smallest eigenvalue")


def check_pca_normal(pca_normal, verbose=True):
    """Self-check of ``pca_normal(P) -> (3,)``: the unit normal (any sign) of a neighbourhood ``P`` (k, 3).

    Cases: points on a tilted plane far from the origin (exact), a noisy elongated patch, and a patch whose largest
    spread is not along an axis.

    Examples
    --------
    >>> check_pca_normal(_reference_pca_normal, verbose=False).passed
    True
    """
    rng = np.random.default_rng(10)

    def run(f, P):
        return _diagnose_pca(_as_normal(f(P.copy())), P)

    def plane(f):
        g = rng.uniform(-1, 1, size=(15, 2))
        P = np.column_stack([g, 0.4 * g[:, 0] - 0.3 * g[:, 1]]) + [5.0, -3.0, 8.0]
        return run(f, P)

    def noisy(f):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        P = (rng.normal(size=(20, 3)) * [2.0, 0.7, 0.05]) @ Q.T + [1.0, 2.0, 3.0]
        return run(f, P)

    def tilted(f):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        P = (rng.normal(size=(12, 3)) * [0.02, 1.0, 3.0]) @ Q.T
        return run(f, P)

    return run_checks("pca_normal", pca_normal, [
        ("points on a tilted plane, far from the origin (exact)", plane),
        ("a noisy elongated patch", noisy),
        ("a thin patch in a random orientation", tilted),
    ], verbose=verbose)


# --- the orientation by visibility ---------------------------------------------------------------------------------
def _reference_orient(X, n, C, seen):
    d = C[seen] - X
    score = np.sum((d / np.linalg.norm(d, axis=1, keepdims=True)) @ n)
    return n if score >= 0 else -n


def _diagnose_orient(out, X, n, C, seen):
    out = np.asarray(out, dtype=float)
    if out.shape != (3,):
        return f"orient_normal must return a (3,) vector; it returned shape {out.shape}"
    ref = _reference_orient(X, n, C, seen)
    if np.allclose(out, ref, atol=1e-9):
        return None
    if np.allclose(out, -ref, atol=1e-9):
        d_all = C - X
        s_all = np.sum((d_all / np.linalg.norm(d_all, axis=1, keepdims=True)) @ n)
        first = (C[seen][0] - X) @ n
        if np.allclose(out, n if s_all >= 0 else -n) and not seen.all():
            return "you used every camera; only the cameras that SEE the point tell which side is outside"
        if np.allclose(out, n if first >= 0 else -n):
            return ("you trusted one camera; a single view can look at the surface almost edge-on, on the wrong side "
                    "of a noisy normal: sum the cosines over all the cameras that see the point")
        d = C[seen] - X
        if np.allclose(out, n if d.sum(0) @ n >= 0 else -n):
            return ("you summed (C_v - X) · n without normalising: divide by ‖C_v − X‖: far cameras would outvote near "
                    "ones (each camera's vote is the cosine of its angle to the normal)")
        if np.allclose(out, n if np.sign(d @ n).sum() >= 0 else -n):
            return ("each camera votes with its cosine, not ±1: a camera that sees the surface head-on counts more "
                    "than two that graze it from behind")
        return ("your normal points away from the cameras: the direction to camera v is C_v - X (not X - C_v), and "
                "the normal must make a positive sum of cosines with these directions")
    if np.allclose(np.abs(out), np.abs(n)) or np.isclose(abs(out @ n), 1.0):
        return "return either n or -n, the whole vector (flip every component together)"
    return "return n or -n (unchanged otherwise): orientation only chooses the sign of the normal"


def check_orient_normal(orient_normal, verbose=True):
    """Self-check of ``orient_normal(X, n, C, seen) -> (3,)``: ``n`` or ``-n``, facing the cameras that see ``X``.

    Cases: one camera, a ring of cameras of which only some see the point, a point whose first observing camera
    looks at it edge-on from the wrong side of a noisy normal, near cameras outvoting a far one (the cosine divides by
    the distance), and one head-on camera outweighing two grazing ones (a cosine, not a ±1 vote).

    Examples
    --------
    >>> check_orient_normal(_reference_orient, verbose=False).passed
    True
    """
    def run(f, X, n, C, seen):
        return _diagnose_orient(f(X.copy(), n.copy(), C.copy(), seen.copy()), X, n, C, seen)

    def one(f):
        X, n = np.array([0.0, 0, 1]), np.array([0.0, 0, 1])
        return (run(f, X, n, np.array([[0.0, 0, 5]]), np.array([True]))
                or run(f, X, n, np.array([[0.0, 0, -5]]), np.array([True])))

    def ring(f):
        C = np.array([[4.0, 0, 0], [3.5, 1.5, 0], [3.5, -1.5, 0.5],                 # these see the point
                      [-4.0, 0, 0], [-3.5, 1, 0], [-3.5, -1, 0], [-3, 2, 1], [-3, -2, -1]])   # these are behind
        seen = np.arange(8) < 3
        X = np.array([0.1, 0.0, 0.0])
        n = _unit(np.array([-1.0, 0.1, 0.2]))                     # stored pointing inward
        return run(f, X, n, C, seen)

    def grazing(f):
        X = np.zeros(3)
        n = _unit(np.array([0.05, 0.0, 1.0]))
        C = np.array([[-8.0, 0, 0.1], [0.0, 3, 4], [1.0, -3, 4], [0.5, 0, 5]])  # the first one: edge-on, behind
        seen = np.ones(4, bool)
        return run(f, X, -n, C, seen)

    def near_far(f):
        X, n = np.zeros(3), np.array([0.0, 0, 1])
        C = np.array([[0.1, 0, -0.5], [-0.1, 0, -0.5], [0.0, 0, 10]])       # two near cameras behind, one far in front
        return run(f, X, n, C, np.ones(3, bool))                            # cosines -0.98, -0.98, +1: expect -n

    def cosine_vote(f):
        X, n = np.zeros(3), np.array([0.0, 0, 1])
        s = np.sqrt(0.99)
        C = 4 * np.array([[np.sqrt(0.19), 0, 0.9], [s, 0, -0.1], [-s, 0, -0.1]])   # cosines 0.9, -0.1, -0.1
        return run(f, X, n, C, np.ones(3, bool))                            # 0.9 - 0.2 > 0: expect n (votes: -1)

    return run_checks("orient_normal", orient_normal, [
        ("one camera in front, then behind", one),
        ("cameras all around, three of which see the point", ring),
        ("the first observing camera is edge-on", grazing),
        ("near and far cameras", near_far),
        ("one camera head-on, two grazing from behind", cosine_vote),
    ], verbose=verbose)


# --- the most frontal view ------------------------------------------------------------------------------------------
def _diagnose_frontal(out, X, normals, C, visible):
    out = np.asarray(out)
    if out.shape != (len(X),):
        return f"most_frontal_view must return an (N,) array of view indices for N = {len(X)}; got shape {out.shape}"
    if out.dtype.kind not in "iu":
        return f"return integer view indices; got dtype {out.dtype}"
    ref = most_frontal_view(X, normals, C, visible)
    if np.array_equal(out, ref):
        return None
    seen = visible.any(axis=0)
    if np.array_equal(out[seen], ref[seen]):
        return "a vertex that no view sees must get -1 (np.argmax of nothing but -inf returns 0, a real view)"
    d = C[:, None, :] - X[None]
    cos = np.einsum("vni,ni->vn", d, normals) / np.linalg.norm(d, axis=-1)
    dots = np.einsum("vni,ni->vn", d, normals)
    masked = np.where(visible, cos, -np.inf)
    if np.array_equal(out[seen], np.argmax(cos, axis=0)[seen]):
        return ("you ignored visibility: choose among the views that SEE the vertex (an occluded view sees another "
                "surface)")
    if np.array_equal(out[seen], np.argmin(np.where(visible, cos, np.inf), axis=0)[seen]):
        return "you took the least frontal view: the most frontal one has the LARGEST cosine"
    if np.array_equal(out[seen], np.argmax(np.where(visible, dots, -np.inf), axis=0)[seen]):
        return ("you compared n · (C - X) without dividing by the distance ||C - X||: that favours far cameras; "
                "compare cosines")
    ranks = [int(np.argmax(masked[visible[:, i], i])) for i in np.flatnonzero(seen)]
    if np.array_equal(out[seen], ranks):
        return "you returned the position among the visible views; return the view's own index (0..V-1)"
    return (f"{int(np.sum(out != ref))} of {len(X)} vertices get another view: among the views that see the vertex, "
            "take the one with the largest cos = n · (C - X) / ||C - X||; -1 when none sees it")


def check_most_frontal_view(frontal, verbose=True):
    """Self-check of ``most_frontal_view(X, normals, C, visible) -> (N,) int`` (-1 where no view sees a vertex).

    Cases: a hand-made vertex and three cameras, a random scene with occlusions (random visibility), and vertices
    that no view sees.

    Examples
    --------
    >>> check_most_frontal_view(most_frontal_view, verbose=False).passed
    True
    """
    rng = np.random.default_rng(12)

    def run(f, X, normals, C, visible):
        return _diagnose_frontal(f(X.copy(), normals.copy(), C.copy(), visible.copy()), X, normals, C, visible)

    def small(f):
        X = np.zeros((2, 3))
        normals = np.array([[0.0, 0, 1], [1.0, 0, 0]])
        C = np.array([[0.0, 0.5, 2], [12.0, 0, 9], [2.0, 0, 0.3]])      # far camera 1 has the largest n · (C - X)
        visible = np.array([[True, True], [True, True], [False, True]])
        return run(f, X, normals, C, visible)

    def scene(f):
        a = np.linspace(0, 2 * np.pi, 10, endpoint=False)
        C = np.column_stack([3 * np.cos(a), 3 * np.sin(a), rng.uniform(-1, 1, 10)]) * rng.uniform(1, 3, (10, 1))
        X = rng.normal(scale=0.3, size=(40, 3))
        normals = rng.normal(size=(40, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        visible = rng.random((10, 40)) < 0.4
        visible[0, ~visible.any(axis=0)] = True                  # every vertex seen by some view here
        return run(f, X, normals, C, visible)

    def unseen(f):
        X = np.zeros((3, 3))
        normals = np.array([[0.0, 0, 1]] * 3)
        C = np.array([[0.0, 0, 5], [0, 4, 3]])
        visible = np.array([[True, False, False], [False, True, False]])
        return run(f, X, normals, C, visible)

    return run_checks("most_frontal_view", frontal, [
        ("two vertices, three cameras (one far, one not seeing)", small),
        ("a random scene with random occlusions", scene),
        ("a vertex no view sees gets -1", unseen),
    ], verbose=verbose)
