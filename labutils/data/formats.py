"""Text files of the structure-from-motion command lines: VGG track files, calibration files, and the JSON result.

Every reader names the file and the line of the first problem it finds (``ValueError``); every writer checks its
input first and writes atomically (a temporary file in the same folder, renamed into place, removed on failure).
PLY point clouds and meshes are :mod:`labutils.data.ply`.
"""
import json
from pathlib import Path

import numpy as np

from ..core.cli import write_atomically
from ..core.validation import as_points, as_tracks


def _numeric_rows(path, what):
    """(line number, list of floats) for each non-blank line of ``path`` ('#' starts a comment)."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the {what} file ({exc})") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        vals = []
        for col, tok in enumerate(tokens, 1):
            try:
                val = float(tok)
            except ValueError:
                raise ValueError(f"{path}, line {lineno}, column {col}: {tok!r} is not a number") from None
            if not np.isfinite(val):
                raise ValueError(f"{path}, line {lineno}, column {col}: {tok!r} is not a finite number")
            vals.append(val)
        rows.append((lineno, vals))
    if not rows:
        raise ValueError(f"{path}: the {what} file holds no numbers")
    return rows


def read_tracks(path):
    """Read a VGG track file: one row per track, ``x y`` for each view, ``-1 -1`` where unseen.

    (The format of the dinosaur's ``viff`` array, 4,983 rows × 72 columns.) Blank lines and text after
    ``#`` are ignored.

    Returns
    -------
    tracks : (V, T, 2) ndarray
        NaN where unseen, like ``Scene.tracks``.

    Raises
    ------
    ValueError
        Naming the file and line: a non-numeric or non-finite entry, an odd number of columns, a row
        whose length differs from the first, fewer than 2 views, or a half-missing observation.
    """
    rows = _numeric_rows(path, "tracks")
    first, n = rows[0][0], len(rows[0][1])
    if n % 2:
        raise ValueError(f"{path}, line {first}: {n} numbers, an odd count; a track row holds an x y pair per view")
    if n < 4:
        raise ValueError(f"{path}, line {first}: {n} numbers = {n // 2} view; at least 2 views (4 columns) are needed")
    for lineno, vals in rows:
        if len(vals) != n:
            raise ValueError(f"{path}, line {lineno}: {len(vals)} numbers, but line {first} has {n} "
                             f"(an x y pair for each of {n // 2} views)")
    a = np.array([vals for _, vals in rows]).reshape(len(rows), n // 2, 2)
    miss = a == -1
    half = miss[..., 0] != miss[..., 1]
    if half.any():
        k, v = np.argwhere(half)[0]
        raise ValueError(f"{path}, line {rows[k][0]}: view {v} has {a[k, v].tolist()}; an unseen observation "
                         "is '-1 -1'")
    a[miss.all(-1)] = np.nan
    return a.transpose(1, 0, 2)


def read_calibration(path, n_views):
    """Read K: one 3×3 matrix shared by all views (3 rows) or one per view stacked (3·V rows).

    Returns
    -------
    K : (V, 3, 3) ndarray
        Scaled so that ``K[2, 2] == 1``.

    Raises
    ------
    ValueError
        Naming the file and line: a row without exactly 3 numbers, a row count other than 3 or 3·V,
        a last row that is not ``0 0 k`` (k ≠ 0), or a singular matrix.
    """
    rows = _numeric_rows(path, "calibration")
    for lineno, vals in rows:
        if len(vals) != 3:
            raise ValueError(f"{path}, line {lineno}: {len(vals)} numbers; each row of K holds 3")
    if len(rows) not in (3, 3 * n_views):
        raise ValueError(f"{path}: {len(rows)} rows; expected 3 (one K shared by all views) or {3 * n_views} "
                         f"(one 3x3 K per view for the {n_views} views of the tracks file)")
    Ks = np.array([vals for _, vals in rows]).reshape(-1, 3, 3)
    for m, K in enumerate(Ks):
        lines = f"lines {rows[3 * m][0]}-{rows[3 * m + 2][0]}"
        who = f" (view {m})" if len(Ks) > 1 else ""
        if K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] == 0:
            raise ValueError(f"{path}, line {rows[3 * m + 2][0]}{who}: the last row of K must be '0 0 k' with k != 0; "
                             f"got {K[2].tolist()}")
        K = K / K[2, 2]
        if abs(np.linalg.det(K)) <= 1e-12 * np.abs(K).max() ** 3:
            raise ValueError(f"{path}, {lines}{who}: K is singular (det = {np.linalg.det(K):.3g})")
        Ks[m] = K
    return np.repeat(Ks, n_views, axis=0) if len(Ks) == 1 else Ks


def write_tracks(path, tracks):
    """Write ``tracks`` (V, T, 2), NaN where unseen, as a VGG track file (inverse of :func:`read_tracks`)."""
    tracks = as_tracks(tracks, min_views=2)
    a = tracks.transpose(1, 0, 2).reshape(tracks.shape[1], -1)
    write_atomically(path, "".join(" ".join("-1" if np.isnan(v) else repr(float(v)) for v in row) + "\n" for row in a))


def read_result_json(path):
    """Read a RESULT.json written by :meth:`Reconstruction.to_json` back into arrays.

    Returns
    -------
    R : (V, 3, 3) ndarray
    t : (V, 3) ndarray
        NaN for views that were not registered.
    X : (T', 3) ndarray
        The points, in the file's order.
    track : (T',) int ndarray
        Their track (row) indices.
    """
    d = json.loads(Path(path).read_text())
    V = len(d["cameras"])
    R, t = np.full((V, 3, 3), np.nan), np.full((V, 3), np.nan)
    for v, cam in enumerate(d["cameras"]):
        if cam is not None:
            R[v], t[v] = cam["R"], cam["t"]
    X = np.array([p["X"] for p in d["points"]], float).reshape(-1, 3)
    track = np.array([p["track"] for p in d["points"]], int)
    return R, t, X, track


def ply_text(X):
    """An ASCII PLY file (as a string) holding the points ``X`` (N, 3).

    >>> print(ply_text(np.array([[1.0, 2.0, 3.5]])), end="")
    ply
    format ascii 1.0
    comment written by labutils
    element vertex 1
    property double x
    property double y
    property double z
    end_header
    1.0 2.0 3.5
    """
    X = as_points(X, "X", dim=3, min_n=0)
    head = ["ply", "format ascii 1.0", "comment written by labutils", f"element vertex {len(X)}",
            "property double x", "property double y", "property double z", "end_header"]
    return "\n".join(head + [" ".join(repr(float(c)) for c in p) for p in X]) + "\n"
