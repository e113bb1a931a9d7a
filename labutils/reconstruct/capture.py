"""A capture check before the long work: is this folder of photos likely to reconstruct, and what to reshoot.

Per image: sharpness (variance of the Laplacian of the working image) and feature count; per pair: verified
inliers; the view graph (an edge where a pair keeps ``min_inliers`` verified matches) and its components. Nothing
is judged against a constant tuned on one data set: an image is *blurred* or *poor* relative to the set's own median
(a third of it), and a view is *isolated* when it has no edge to the largest component. What to reshoot is said in
words, e.g. "views 7-9 share too little with the rest: take two more photos between view 6 and view 7".
"""
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from ..core.validation import as_array, as_count

__all__ = ["CaptureReport", "capture_check", "sharpness"]

RELATIVE = 1 / 3          # below a third of the set's median: flagged


def sharpness(gray: np.ndarray) -> float:
    """Variance of the Laplacian of a grey image (Pech-Pacheco et al., ICPR 2000): low for a blurred photo.

    >>> img = np.zeros((64, 64), np.uint8); img[:, 32:] = 255
    >>> sharpness(img) > sharpness(cv2.GaussianBlur(img, (0, 0), 3))
    True
    """
    g = as_array(gray, "gray", "(H, W)")
    if g.ndim != 2 or g.size == 0 or not np.all(np.isfinite(g)):
        raise ValueError(f"gray must be a finite, non-empty (H, W) image; got shape {g.shape}")
    return float(cv2.Laplacian(g.astype(np.float32), cv2.CV_32F).var())


def _runs(idx):
    """[3, 4, 5, 9] -> ['3-5', '9']."""
    out, start = [], None
    for k, v in enumerate(idx):
        if start is None:
            start = v
        if k + 1 == len(idx) or idx[k + 1] != v + 1:
            out.append(f"{start}-{v}" if v > start else f"{v}")
            start = None
    return out


@dataclass
class CaptureReport:
    """What :func:`capture_check` found.

    Attributes
    ----------
    names : list of str
    sharpness : (V,) ndarray
    n_features : (V,) ndarray
    pair_inliers : dict
        ``{(i, j): verified matches}`` of every pair tried.
    component : (V,) int ndarray
        Connected component of each view in the view graph; the largest is the one reconstructed.
    problems : list of str
        One line per problem found (blur, few features, isolated views), with what to do.
    ok : bool
        At least two views in the largest component and every view in it.
    """

    names: list
    sharpness: np.ndarray
    n_features: np.ndarray
    pair_inliers: dict
    component: np.ndarray
    problems: list = field(default_factory=list)

    @property
    def largest(self):
        counts = np.bincount(self.component)
        return np.flatnonzero(self.component == np.argmax(counts))

    @property
    def ok(self):
        return len(self.largest) >= 2 and len(self.largest) == len(self.names)

    def degree(self, min_inliers):
        d = np.zeros(len(self.names), int)
        for (i, j), n in self.pair_inliers.items():
            if n >= min_inliers:
                d[i] += 1
                d[j] += 1
        return d

    def text(self):
        """The report as Markdown lines (a table per image, then the problems)."""
        lines = ["| view | image | sharpness | features | component |", "|---:|---|---:|---:|---:|"]
        for v, name in enumerate(self.names):
            lines.append(f"| {v} | {name} | {self.sharpness[v]:.0f} | {self.n_features[v]} | {self.component[v]} |")
        good = sum(1 for n in self.pair_inliers.values() if n > 0)
        lines += ["", f"{good} of {len(self.pair_inliers)} pairs verified; the largest connected group holds "
                      f"{len(self.largest)} of {len(self.names)} views.", ""]
        lines += [f"- {p}" for p in self.problems] or ["- no problem found"]
        return lines


def capture_check(names, grays, n_features, pair_inliers, *, min_inliers=20):
    """Check a photo set from its images, features and pairwise verified matches (module docstring).

    Parameters
    ----------
    names : list of V str
    grays : list of V (H, W) uint8 arrays
        The working images.
    n_features : (V,) int array_like
    pair_inliers : dict
        ``{(i, j): n}`` verified matches of each pair tried (0 for a pair that failed).
    min_inliers : int
        Fewest verified matches for an edge of the view graph.

    Returns
    -------
    CaptureReport

    Examples
    --------
    >>> r = capture_check(["a", "b", "c"], [np.eye(8, dtype=np.uint8) * 255] * 3, [500, 500, 500],
    ...                   {(0, 1): 300, (0, 2): 0, (1, 2): 3})
    >>> r.component.tolist()
    [0, 0, 1]
    >>> print(r.problems[0])
    view 2 (c) shares too little with the rest (at most 3 verified matches with any view): take one or two more
    photos between it and view 1
    """
    V = len(names)
    if len(grays) != V or len(n_features) != V:
        raise ValueError(f"names, grays and n_features must have one entry per view; got {V}, {len(grays)}, "
                         f"{len(n_features)}")
    sharp = np.array([sharpness(g) for g in grays])
    nf = np.array([as_count(n, f"n_features[{v}]", 0) for v, n in enumerate(n_features)], int)
    min_inliers = as_count(min_inliers, "min_inliers")
    ii, jj = [], []
    for (i, j), n in pair_inliers.items():
        if not (0 <= i < V and 0 <= j < V) or i == j:
            raise ValueError(f"pair_inliers has a pair {(i, j)} outside 0..{V - 1}")
        as_count(n, f"pair_inliers[{(i, j)}]", 0)
        if n >= min_inliers:
            ii.append(i)
            jj.append(j)
    graph = csr_matrix((np.ones(len(ii)), (ii, jj)), shape=(V, V))
    _, comp = connected_components(graph, directed=False)
    order = np.argsort(-np.bincount(comp), kind="stable")              # component 0 is the largest
    comp = np.argsort(order)[comp]
    report = CaptureReport(list(names), sharp, nf, dict(pair_inliers), comp)
    med_s, med_f = np.median(sharp), np.median(nf)
    for v in np.flatnonzero(sharp < RELATIVE * med_s):
        report.problems.append(f"view {v} ({names[v]}) looks blurred (sharpness {sharp[v]:.0f}, the set's median "
                               f"{med_s:.0f}): retake it steadier or in more light")
    for v in np.flatnonzero(nf < RELATIVE * med_f):
        report.problems.append(f"view {v} ({names[v]}) has few features ({nf[v]}, the set's median {med_f:.0f}): "
                               "more texture in view, less glare, or closer")
    outside = np.flatnonzero(comp != 0)
    for run in _runs(outside.tolist()):
        a, b = (int(s) for s in (run.split("-") * 2)[:2])
        best = max((n for (i, j), n in pair_inliers.items() if (a <= i <= b) != (a <= j <= b)), default=0)
        near = [v for v in (a - 1, b + 1) if 0 <= v < V and comp[v] == 0]
        where = f"between it and view {near[0]}" if near else "that overlap both it and the others"
        label = f"view {a} ({names[a]})" if a == b else f"views {a}-{b}"
        report.problems.append(f"{label} {'shares' if a == b else 'share'} too little with the rest (at most "
                               f"{best} verified matches with any view): take {'one or two' if a == b else 'two'} "
                               f"more photos {where}")
    if V < 3:
        report.problems.append(f"{V} photos: take at least 3 (better 10 or more), each overlapping its neighbours")
    return report
