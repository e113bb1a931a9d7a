"""Self-checks of notebook 09 (global SfM): chordal rotation averaging and camera centres from pairwise directions.

Each check runs a student's function on a few cases and prints pass or a hint naming the likely mistake, found by
comparing the answer with the typical wrong variants (the relative rotations placed in the wrong block, the
weights or the degree normalisation left out, a reflection left in, no projection onto SO(3); the gauge not
lifted, the centres mirrored, the translations used without turning them into the world frame ...).
"""
import numpy as np

from ..core.geometry import rotation_from_angle_axis
from ..core.metrics import rotation_error_deg
from ..pose.global_translations import centres_from_directions
from ..pose.rotation_averaging import chordal_rotation_averaging, project_to_so3
from .runner import run_checks

# ---------------------------------------------------------------------------------------------------------------
# exercise 1: chordal rotation averaging
# ---------------------------------------------------------------------------------------------------------------


def _graph(seed, n_views=8, extra=6, noise_deg=0.0, weights=False):
    """A ring of views plus a few chords; relative rotations ``R_j R_iᵀ`` with optional noise."""
    rng = np.random.default_rng(seed)
    R = rotation_from_angle_axis(rng.normal(size=(n_views, 3)))
    ring = [(v, (v + 1) % n_views) for v in range(n_views)]
    chords = set()
    while len(chords) < extra:
        i, j = sorted(rng.choice(n_views, 2, replace=False))
        if (i, j) not in ring and (j, i) not in ring and j - i != n_views - 1:
            chords.add((int(i), int(j)))
    pairs = np.array(ring + sorted(chords))
    R_rel = R[pairs[:, 1]] @ np.swapaxes(R[pairs[:, 0]], 1, 2)
    if noise_deg > 0:
        noise = rng.normal(scale=np.radians(noise_deg) / np.sqrt(3), size=(len(pairs), 3))
        R_rel = rotation_from_angle_axis(noise) @ R_rel
    w = rng.uniform(20, 400, len(pairs)) if weights else None
    return pairs, R_rel, w, R


def _aligned_error(R_est, R_ref):
    """Largest angle (degrees) between ``R_est[i] Q`` and ``R_ref[i]`` for the best global rotation Q."""
    Q = project_to_so3(np.einsum("vji,vjk->ik", R_est, R_ref))
    return float(rotation_error_deg(R_est @ Q, R_ref).max())


def _unnormalised(pairs, R_rel, n_views, w):
    """The spectral method on G itself (no degree normalisation): a wrong answer's twin when degrees differ."""
    w = np.ones(len(pairs)) if w is None else w
    G = np.zeros((n_views, 3, n_views, 3))
    for (i, j), Rij, wk in zip(pairs, R_rel, w):
        G[j, :, i] += wk * Rij
        G[i, :, j] += wk * Rij.T
    M = np.linalg.eigh(G.reshape(3 * n_views, 3 * n_views))[1][:, -3:].reshape(n_views, 3, 3)
    if np.sum(np.sign(np.linalg.det(M))) < 0:
        M[:, :, 0] *= -1
    return project_to_so3(M)


def _diagnose_chordal(R, pairs, R_rel, w, n_views, tol_deg=1e-6):
    R = np.asarray(R, float)
    if R.shape != (n_views, 3, 3):
        return f"chordal_rotations must return shape ({n_views}, 3, 3), one rotation per view; it returned {R.shape}"
    if not np.all(np.isfinite(R)):
        return "chordal_rotations returned NaN or inf"
    det = np.linalg.det(R)
    if np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() > 1e-6:
        return ("your matrices are not orthonormal: project each 3×3 block of the eigenvectors onto SO(3), "
                "U diag(1, 1, det(U Vᵀ)) Vᵀ from its SVD U S Vᵀ")
    if np.any(det < 0):
        return ("some of your matrices have det -1 (reflections): the projection onto SO(3) is U diag(1, 1, det(U Vᵀ)) "
                "Vᵀ, and the three eigenvectors give M only up to an orthogonal Q that may be a reflection — flip one "
                "column of M when most blocks have a negative determinant")
    ref = chordal_rotation_averaging(pairs, R_rel, n_views, w)
    if _aligned_error(R, ref) < tol_deg:
        return None
    if _aligned_error(R, chordal_rotation_averaging(pairs, np.swapaxes(R_rel, 1, 2), n_views, w)) < tol_deg:
        return ("you used R_i = R_ij R_j: the convention is R_j = R_ij R_i (camera j relative to camera i), so block "
                "(j, i) of M Mᵀ is R_j R_iᵀ = R_ij and block (i, j) is R_ijᵀ")
    if w is not None and _aligned_error(R, chordal_rotation_averaging(pairs, R_rel, n_views)) < tol_deg:
        return "the weights are ignored: block (j, i) of G is w_ij R_ij, and the degree d_i is Σ_j w_ij"
    if _aligned_error(R, _unnormalised(pairs, R_rel, n_views, w)) < tol_deg:
        return ("you took the eigenvectors of G itself: when the views have different degrees, G M = D M, so use "
                "the leading eigenvectors of D^-½ G D^-½ and then M = D^-½ Y")
    return (f"your rotations differ from the chordal solution by {_aligned_error(R, ref):.2g}° (after the best global "
            "rotation): G has blocks G_ji = w_ij R_ij and G_ij = w_ij R_ijᵀ; take the three eigenvectors of "
            "D^-½ G D^-½ with the largest eigenvalues, M = D^-½ Y, and project each block onto SO(3)")


def check_chordal_rotations(chordal_rotations, verbose=True):
    """Self-check of ``chordal_rotations(pairs, R_rel, weights, n_views) -> R (V, 3, 3)``, ``R_j ≈ R_ij R_i``.

    Cases: a noise-free ring with chords (the true rotations, up to one global rotation), noisy relative rotations
    with weights (the chordal solution), and views of very different degree. The answer is compared after the best
    global rotation, so any gauge is accepted.

    Examples
    --------
    >>> check_chordal_rotations(lambda p, R, w, n: chordal_rotation_averaging(p, R, n, w), verbose=False).passed
    True
    """
    def exact(f):
        pairs, R_rel, _, R = _graph(0)
        R_est = f(pairs.copy(), R_rel.copy(), None, len(R))
        d = _diagnose_chordal(R_est, pairs, R_rel, None, len(R))
        if d is None and _aligned_error(np.asarray(R_est, float), R) > 1e-6:
            return "noise-free relative rotations must give the true rotations exactly (up to one global rotation)"
        return d

    def noisy(f):
        pairs, R_rel, w, R = _graph(1, n_views=10, extra=12, noise_deg=3.0, weights=True)
        return _diagnose_chordal(f(pairs.copy(), R_rel.copy(), w.copy(), len(R)), pairs, R_rel, w, len(R))

    def degrees(f):
        pairs, R_rel, w, R = _graph(2, n_views=9, extra=0, noise_deg=2.0, weights=True)
        hub = np.array([[0, v] for v in range(2, 8)])             # view 0 gets many more edges than the others
        pairs = np.vstack([pairs, hub])
        R_rel = np.concatenate([R_rel, R[hub[:, 1]] @ np.swapaxes(R[hub[:, 0]], 1, 2)])
        w = np.concatenate([w, np.full(len(hub), 300.0)])
        return _diagnose_chordal(f(pairs.copy(), R_rel.copy(), w.copy(), len(R)), pairs, R_rel, w, len(R))

    return run_checks("chordal_rotations", chordal_rotations, [
        ("a noise-free ring with chords: the true rotations", exact),
        ("noisy relative rotations (3°) with weights", noisy),
        ("one view joined to most others (unequal degrees)", degrees),
    ], verbose=verbose)


# ---------------------------------------------------------------------------------------------------------------
# exercise 2: camera centres from pairwise directions
# ---------------------------------------------------------------------------------------------------------------


def _normalised(C):
    C = np.asarray(C, float) - np.mean(C, axis=0)
    return C / np.sqrt((C ** 2).sum(1).mean())


def _centres_case(seed, n_views=7, noise_deg=0.0, line=False):
    rng = np.random.default_rng(seed)
    if line:
        C = np.outer(np.arange(n_views, dtype=float), [0.1, 0.0, 1.0])
    else:
        a = np.sort(rng.uniform(0, 2 * np.pi, n_views))
        C = np.stack([np.cos(a), np.sin(a), 0.1 * rng.normal(size=n_views)], axis=1)
    pairs = np.array([(i, j) for i in range(n_views) for j in range(i + 1, n_views) if j - i <= 3])
    d = C[pairs[:, 1]] - C[pairs[:, 0]]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if noise_deg > 0:
        d = np.einsum("eij,ej->ei", rotation_from_angle_axis(rng.normal(scale=np.radians(noise_deg) / np.sqrt(3),
                                                                         size=(len(d), 3))), d)
    return pairs, d, C


def _diagnose_centres(C_est, pairs, d, n_views, C_ref):
    C_est = np.asarray(C_est, float)
    if C_est.shape != (n_views, 3):
        return (f"centres_from_directions must return shape ({n_views}, 3), one centre per view; it returned "
                f"{C_est.shape}")
    if not np.all(np.isfinite(C_est)):
        return "centres_from_directions returned NaN or inf"
    spread = np.sqrt(((C_est - C_est.mean(0)) ** 2).sum(1).mean())
    if spread < 1e-9 * max(np.abs(C_est).max(), 1e-300):
        return ("all your centres are the same point: that is the translation gauge (every centre moved together "
                "solves the equations) — lift it (add μ N Nᵀ with N the stacked identities) or hold one centre at 0, "
                "and take the next eigenvector")
    got, ref = _normalised(C_est), _normalised(C_ref)
    if np.abs(got - ref).max() < 1e-6:
        return None
    if np.abs(got + ref).max() < 1e-6:
        return ("your centres are mirrored through their mean: the eigenvector is defined up to sign; choose it so "
                "that Σ d_ij · (C_j - C_i) > 0 (C_j lies in the direction d_ij from C_i)")
    return (f"your centres differ from the solution by up to {np.abs(got - ref).max():.2g} (both moved to mean 0 and "
            "RMS spread 1): each pair gives [d_ij]× (C_j - C_i) = 0 (three rows, rank 2); stack them for the 3V "
            "unknowns and take the eigenvector of AᵀA with the smallest eigenvalue once the gauge is lifted")


def check_centres_from_directions(centres_from_directions_fn, verbose=True):
    """Self-check of ``centres_from_directions(pairs, directions, n_views) -> C (V, 3)``, ``d_ij ∝ C_j - C_i``.

    Cases: noise-free directions around a ring (the true centres, up to translation and a positive scale), noisy
    directions (the least-squares solution), and centres on one line (not determined: a ``ValueError`` is
    expected).

    Examples
    --------
    >>> check_centres_from_directions(lambda p, d, n: centres_from_directions(p, d, n), verbose=False).passed
    True
    """
    def ring(f, pairs, d, n):
        try:
            return f(pairs.copy(), d.copy(), n)
        except ValueError as exc:
            raise ValueError(f"{exc} — but a ring of cameras *is* determined: the three other null vectors of AᵀA are "
                             "the translation gauge (every centre moved together); lift it (add μ N Nᵀ, N the stacked "
                             "identities) before judging the second-smallest eigenvalue") from None

    def exact(f):
        pairs, d, C = _centres_case(0)
        return _diagnose_centres(ring(f, pairs, d, len(C)), pairs, d, len(C), C)

    def noisy(f):
        pairs, d, C = _centres_case(1, n_views=9, noise_deg=2.0)
        return _diagnose_centres(ring(f, pairs, d, len(C)), pairs, d, len(C), centres_from_directions(pairs, d, len(C)))

    def line(f):
        pairs, d, C = _centres_case(2, line=True)
        try:
            C_est = f(pairs.copy(), d.copy(), len(C))
        except ValueError:
            return None
        return ("centres on one line (forward motion) are not determined by directions alone — any spacing along the "
                f"line fits — yet you returned {np.round(np.asarray(C_est, float)[:2], 3).tolist()}...: raise "
                "ValueError when the second-smallest eigenvalue is ~0 (relative to the largest)")

    return run_checks("centres_from_directions", centres_from_directions_fn, [
        ("noise-free directions around a ring: the true centres", exact),
        ("noisy directions (2°): the least-squares centres", noisy),
        ("centres on one line: ValueError (not determined)", line),
    ], verbose=verbose)
