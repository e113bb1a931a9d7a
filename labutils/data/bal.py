"""Reading and writing "Bundle Adjustment in the Large" (BAL) problem files (Agarwal et al., ECCV 2010).

The format (plain text, whitespace separated)::

    n_cameras n_points n_observations
    cam point x y                        (n_observations lines)
    9 numbers per camera                 (ω (Rodrigues), t, f, k1, k2; usually one number a line)
    3 numbers per point                  (X Y Z)

The camera looks down -z: ``P = R X + t``, ``p = -P[:2] / P[2]``, pixel
``f · (1 + k1‖p‖² + k2‖p‖⁴) · p`` about the image centre, y up (the ``'bal'`` model of
:mod:`labutils.bundle.adjust`). Every error names the line of the file where it was found.
"""
import bz2
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.cli import write_atomically
from ..core.validation import as_points


class BALFormatError(ValueError):
    """A BAL file is malformed; the message names the file and the line."""


@dataclass
class BALProblem:
    """A BAL problem: the bundle-adjustment arrays of :mod:`labutils.bundle.adjust` with the BAL camera model.

    Attributes
    ----------
    camera_params : (V, 9) ndarray
        ``ω (3), t (3), f, k1, k2`` per camera.
    points_3d : (M, 3) ndarray
    camera_indices, point_indices : (n_obs,) int ndarray
    points_2d : (n_obs, 2) ndarray
        Pixels about the image centre, y up.
    """

    camera_params: np.ndarray
    points_3d: np.ndarray
    camera_indices: np.ndarray
    point_indices: np.ndarray
    points_2d: np.ndarray

    @property
    def n_cameras(self):
        return self.camera_params.shape[0]

    @property
    def n_points(self):
        return self.points_3d.shape[0]

    @property
    def n_observations(self):
        return self.points_2d.shape[0]


def _err(where, lineno, msg):
    return BALFormatError(f"{where}: line {lineno}: {msg}")


_INT_MAX = np.iinfo(np.int64).max


def _parse_int(tok, where, lineno, what):
    try:
        value = int(tok)
    except ValueError:
        raise _err(where, lineno, f"{what} must be an integer; got {tok!r}") from None
    if abs(value) > _INT_MAX:
        raise _err(where, lineno, f"{what} {tok} is too large")
    return value


def parse_bal(text, where="<string>"):
    """Parse the text of a BAL file into a :class:`BALProblem`.

    Raises
    ------
    BALFormatError
        (a ``ValueError``) for a missing or bad header, a truncated file, a line with the wrong number
        of fields, a non-numeric or non-finite value or one larger than :data:`MAX_ABS` (1e12) in magnitude, an
        index out of range, or data after the end; the message names the line.

    Examples
    --------
    >>> p = parse_bal("1 2 2\\n0 0 1.5 -2\\n0 1 3 4\\n" + "0\\n" * 6 + "500\\n0\\n0\\n" + "0 0 -5\\n1 0 -5\\n")
    >>> p.camera_params.shape, p.points_3d.tolist(), p.camera_indices.tolist()
    ((1, 9), [[0.0, 0.0, -5.0], [1.0, 0.0, -5.0]], [0, 0])
    >>> parse_bal("1 2 3\\n0 0 1.5 -2\\n")
    Traceback (most recent call last):
    ...
    labutils.data.bal.BALFormatError: <string>: line 3: the file ends after 1 of 3 observation lines
    """
    lines = text.splitlines()
    # header: the first non-empty line
    i = 0
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i == len(lines):
        raise _err(where, 1, "the file is empty (expected 'n_cameras n_points n_observations')")
    head = lines[i].split()
    if len(head) != 3:
        raise _err(where, i + 1, f"the header must be 'n_cameras n_points n_observations'; got {lines[i].strip()!r}")
    V, M, N = (_parse_int(tok, where, i + 1, name)
               for tok, name in zip(head, ("n_cameras", "n_points", "n_observations")))
    if V < 1 or M < 1 or N < 1:
        raise _err(where, i + 1, f"the counts must be positive; got {V} cameras, {M} points, {N} observations")
    if max(V, M, N) > 10 ** 9:
        raise _err(where, i + 1, f"the counts are implausibly large ({V}, {M}, {N})")
    first_obs = i + 1
    obs_lines = lines[first_obs:first_obs + N]
    if len(obs_lines) < N:
        raise _err(where, len(lines) + 1, f"the file ends after {len(obs_lines)} of {N} observation lines")
    fields = [ln.split() for ln in obs_lines]
    bad = [j for j, f in enumerate(fields) if len(f) != 4]
    if bad:
        j = bad[0]
        raise _err(where, first_obs + j + 1, f"an observation line must be 'camera point x y' (4 fields); got "
                   f"{len(fields[j])} field(s): {obs_lines[j].strip()!r} (wrong n_observations in the header?)")
    try:
        idx = np.array([(int(f[0]), int(f[1])) for f in fields], dtype=np.int64).reshape(N, 2)
    except ValueError:
        j = next(j for j, f in enumerate(fields) if not all(_is_int(t) for t in f[:2]))
        raise _err(where, first_obs + j + 1,
                   f"camera and point indices must be integers; got {obs_lines[j].strip()!r}") from None
    except OverflowError:
        j = next(j for j, f in enumerate(fields) if max(abs(int(f[0])), abs(int(f[1]))) > _INT_MAX)
        raise _err(where, first_obs + j + 1, f"an index is too large: {obs_lines[j].strip()!r}") from None
    xy = _to_float([t for f in fields for t in f[2:]], where, lambda j: first_obs + j // 2 + 1, "pixel coordinates")
    xy = xy.reshape(N, 2)
    for col, upper, what in ((0, V, "camera"), (1, M, "point")):
        out = np.flatnonzero((idx[:, col] < 0) | (idx[:, col] >= upper))
        if out.size:
            j = int(out[0])
            raise _err(where, first_obs + j + 1, f"{what} index {idx[j, col]} is out of range (the header says "
                       f"{upper} {what}s: 0..{upper - 1})")
    # parameters: a stream of numbers, any number a line; remember each number's line
    rest = lines[first_obs + N:]
    nxt = next((j for j, ln in enumerate(rest) if ln.strip()), None)
    if nxt is not None:
        f = rest[nxt].split()
        if len(f) == 4 and _is_int(f[0]) and _is_int(f[1]):
            raise _err(where, i + 1, f"the header says {N} observations, but line {first_obs + N + nxt + 1} is one "
                       "more observation line ('camera point x y'): the count in the header is too small")
    toks, tok_line = [], []
    for j, ln in enumerate(rest):
        f = ln.split()
        toks.extend(f)
        tok_line.extend([first_obs + N + j + 1] * len(f))
    need = 9 * V + 3 * M
    if len(toks) < need:
        part = "camera parameters" if len(toks) < 9 * V else "point coordinates"
        raise _err(where, len(lines) + 1, f"the file ends early: {need} parameter values expected after the "
                   f"observations ({9 * V} for {V} cameras, {3 * M} for {M} points), found {len(toks)} "
                   f"(missing {part})")
    if len(toks) > need:
        raise _err(where, tok_line[need], f"unexpected data after the {need} parameter values "
                   "(wrong counts in the header?)")
    vals = _to_float(toks, where, lambda j: tok_line[j], "parameters")
    cams = vals[:9 * V].reshape(V, 9)
    pts = vals[9 * V:].reshape(M, 3)
    return BALProblem(camera_params=cams, points_3d=pts, camera_indices=idx[:, 0], point_indices=idx[:, 1],
                      points_2d=xy)


def _is_int(tok):
    try:
        int(tok)
        return True
    except ValueError:
        return False


MAX_ABS = 1e12      # no real BAL value (pixel, rotation, translation, focal length, distortion, coordinate) is near
# it; a larger one is a corrupt file (1e300 made the cost inf and the "solution" the unchanged input), refused by line


def _to_float(tokens, where, line_of, what):
    """Convert a list of strings to floats; on failure name the line (``line_of(index)``) of the first bad one:
    not a number, not finite, or larger in magnitude than :data:`MAX_ABS` (its square would overflow the cost)."""
    try:
        out = np.array(list(map(float, tokens)))
        bad = np.flatnonzero(~(np.abs(out) <= MAX_ABS))
        j = int(bad[0]) if bad.size else None
    except ValueError:
        j = next(j for j, t in enumerate(tokens) if not _is_float(t))
    if j is not None:
        if _is_float(tokens[j]):
            raise _err(where, line_of(j), f"{what} must be at most {MAX_ABS:g} in magnitude; got {tokens[j]!r}")
        raise _err(where, line_of(j), f"{what} must be finite numbers; got {tokens[j]!r}")
    return out


def _is_float(tok):
    try:
        return np.isfinite(float(tok))
    except ValueError:
        return False


def read_bal(path):
    """Read a BAL file (see :func:`parse_bal`); ``.bz2`` files are decompressed.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    BALProblem

    Raises
    ------
    BALFormatError
        Malformed file, naming the line. ``FileNotFoundError`` if it does not exist.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise OSError(f"{path}: cannot read the BAL file ({exc.strerror or exc})") from None
    if path.suffix == ".bz2":
        try:
            raw = bz2.decompress(raw)
        except (OSError, ValueError, EOFError) as exc:
            raise BALFormatError(f"{path}: not a valid bzip2 file ({exc})") from None
    return parse_bal(raw.decode("ascii", errors="replace"), where=str(path))


def check_bal_problem(problem):
    """Check that ``problem`` is a valid :class:`BALProblem` (what :func:`parse_bal` would accept), or ``ValueError``.

    >>> check_bal_problem(BALProblem(np.zeros((1, 6)), np.zeros((1, 3)), np.zeros(1, int), np.zeros(1, int),
    ...                              np.zeros((1, 2))))
    Traceback (most recent call last):
    ...
    ValueError: camera_params must have shape (V, 9) (ω, t, f, k1, k2 per camera); got shape (1, 6)
    """
    cp = np.asarray(problem.camera_params, float)
    if cp.ndim != 2 or cp.shape[1] != 9 or cp.shape[0] < 1:
        raise ValueError(f"camera_params must have shape (V, 9) (ω, t, f, k1, k2 per camera); got shape {cp.shape}")
    if not np.all(np.isfinite(cp)):
        raise ValueError("camera_params has non-finite entries (NaN or inf)")
    X = as_points(problem.points_3d, "points_3d", dim=3)
    x = as_points(problem.points_2d, "points_2d", dim=2)
    for name, a, upper in (("camera_indices", problem.camera_indices, cp.shape[0]),
                           ("point_indices", problem.point_indices, X.shape[0])):
        a = np.asarray(a)
        if a.shape != (x.shape[0],) or (a.size and a.dtype.kind not in "iu"):
            raise ValueError(f"{name} must be {x.shape[0]} integers (one per observation); "
                             f"got {a.dtype} shape {a.shape}")
        bad = np.flatnonzero((a < 0) | (a >= upper))
        if bad.size:
            raise ValueError(f"{name}[{bad[0]}] = {a[bad[0]]} is out of range 0..{upper - 1}")


def format_bal(problem):
    """The text of a BAL file for ``problem`` (numbers in ``%.16e``, so reading it back is exact).

    >>> p = parse_bal("1 1 1\\n0 0 1 2\\n" + "0\\n" * 6 + "500\\n0\\n0\\n" + "0\\n0\\n-5\\n")
    >>> parse_bal(format_bal(p)).camera_params[0, 6]
    np.float64(500.0)
    """
    check_bal_problem(problem)
    p = problem
    out = [f"{p.n_cameras} {p.n_points} {p.n_observations}"]
    out += [f"{c} {j} {x:.16e} {y:.16e}" for c, j, (x, y) in zip(p.camera_indices.tolist(), p.point_indices.tolist(),
                                                                 p.points_2d.tolist())]
    out += [f"{v:.16e}" for v in np.asarray(p.camera_params, float).ravel().tolist()]
    out += [f"{v:.16e}" for v in np.asarray(p.points_3d, float).ravel().tolist()]
    return "\n".join(out) + "\n"


def write_bal(path, problem):
    """Write ``problem`` as a BAL file at ``path``: checked first (:func:`check_bal_problem`), then written
    atomically (a temporary file in the same folder, renamed into place; removed on failure)."""
    write_atomically(path, format_bal(problem))
